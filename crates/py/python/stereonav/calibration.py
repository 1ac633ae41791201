"""Phase 1 of the method: self-calibration of the camera parameters from relative motion.

Landmarks triangulated at two instants and the odometry motion between them must satisfy
eq. (1), ``L_t = Rot_z(dtheta) L_{t+1} + dT``; the mismatch over many frame pairs drives a
Levenberg-Marquardt estimate of the rig file's estimated camera parameters (eq. (2)), with
their covariance and an observability report saying which of them the data can give, and why
not when they cannot.

The data are frame pairs, as two NumPy structured arrays:

- ``observations`` (:data:`OBSERVATION_DTYPE`): one landmark seen at both instants of a
  pair, ``pair`` (the row of ``motions``) and its pixels ``uL0 .. vR1``;
- ``motions`` (:data:`MOTION_DTYPE`): one row per pair, the odometry motion from its first
  frame to its second.

:func:`frame_pairs` builds them from per-frame measurements with landmark ids
(:data:`MEASUREMENT_DTYPE`) and the odometry; :func:`integrate_odometry` gives the motion of
any time span. :func:`calibrate` runs the batch solve; :class:`SelfCalibrator` runs phase 1
pair by pair until it hands over to phase 2.

:func:`calibrate_log` does all of it on a vehicle log (``vehicle-interfaces.md`` section 4):
the board's stream decoded, the landmarks matched and tracked with the odometry, frame pairs
built and solved, in Rust; it returns a :class:`LogCalibration`.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from typing import Any, NamedTuple, Optional, Union, final

import numpy as np
import numpy.typing as npt

from . import _native
from ._errors import InputError, InputTypeError
from ._arrays import readonly as _readonly
from .rig import CAMERA_PARAMETERS, Camera, RigConfig, _camera, _native_rig
from .simulation import ODOMETRY_DTYPE

__all__ = [
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
]

#: One landmark of one frame pair (``vehicle-interfaces.md`` section 1): ``pair`` (``<u4``,
#: the row of the motions array), then ``uL0, vL0, uR0, vR0`` (``<f8``, pixels at the pair's
#: first frame) and ``uL1, vL1, uR1, vR1`` (at its second frame).
OBSERVATION_DTYPE = np.dtype(
    [("pair", "<u4")]
    + [(name, "<f8") for name in ("uL0", "vL0", "uR0", "vR0", "uL1", "vL1", "uR1", "vR1")]
)
#: The motion of one frame pair, in the robot frame at its first frame (eq. (1)): ``t_us``
#: (``<u8``, time of the second frame), ``dx``, ``dy`` (``<f8``, metres), ``dtheta``
#: (``<f8``, radians), ``dt_s`` (``<f8``, seconds) and ``samples`` (``<u4``, odometry samples
#: integrated, for the noise model: each adds ``velocity`` and ``yaw_rate`` noise of the rig).
MOTION_DTYPE = np.dtype(
    [
        ("t_us", "<u8"),
        ("dx", "<f8"),
        ("dy", "<f8"),
        ("dtheta", "<f8"),
        ("dt_s", "<f8"),
        ("samples", "<u4"),
    ]
)
#: One landmark seen in one stereo frame: ``t_us`` (``<u8``, the frame's time), ``id``
#: (``<u4``, the landmark) and ``uL, vL, uR, vR`` (``<f8``, pixels).
MEASUREMENT_DTYPE = np.dtype(
    [("t_us", "<u8"), ("id", "<u4"), ("uL", "<f8"), ("vL", "<f8"), ("uR", "<f8"), ("vR", "<f8")]
)

_OBSERVATION_VALUES = OBSERVATION_DTYPE.names[1:] if OBSERVATION_DTYPE.names else ()
_MOTION_VALUES = ("dx", "dy", "dtheta", "dt_s")
_MEASUREMENT_VALUES = ("uL", "vL", "uR", "vR")
_ODOMETRY_VALUES = ("vx", "vy", "vtheta")
_U32_MAX = (1 << 32) - 1

# The keyword defaults are the Rust ``Default``s (``selfcal::solver::SolverSettings`` and
# ``StableRule``, the replay's ``solve_every``, ``track::PairSettings``), read from the native
# settings objects made without keywords.
_SOLVER = _native.SolverSettings()
_RULE = _native.StableRule()
_PAIRS = _native.PairSettings()
#: The pairing schemes of :func:`calibrate_log`.
_PAIRINGS = ("disjoint", "interleaved")

_F64 = npt.NDArray[np.float64]
_U64 = npt.NDArray[np.uint64]


# --- Results -------------------------------------------------------------------------------


#: How well the data constrain one estimated parameter (a frozen native object, compared by
#: value).
#:
#: Attributes: ``name`` (str, one of :data:`CAMERA_PARAMETERS`), ``prior_sigma`` (float, its
#: prior sigma, rig file ``[prior]``), ``data_sigma`` (float, its sigma from the data alone,
#: ``inf`` when the data say nothing about it), ``posterior_sigma`` (float, from data and prior
#: together), ``observable`` (bool, whether the data constrain it: ``posterior_sigma <=
#: observable_ratio * prior_sigma``; an unobservable parameter is held at its nominal value),
#: ``reason`` (str or None, why it is not observable: the known traps, an upward camera on
#: planar motion cannot give ``f``, planar motion never gives the height, a straight path not
#: the offsets) and ``structural`` (bool, not observable because of one of those traps of the
#: rig and the path rather than for lack of data so far, which more driving may cure and which
#: holds back the hand-over to phase 2).
ParamObservability = _native.ParamObservability


class Correlation(NamedTuple):
    """The largest absolute correlation between two observable estimated parameters."""

    #: One parameter.
    first: str
    #: The other.
    second: str
    #: The correlation coefficient, in ``[-1, 1]``.
    value: float


@final
@dataclasses.dataclass(frozen=True, eq=False)
class Observability:
    """The observability analysis of the estimated parameters.

    Attributes
    ----------
    params : tuple of ParamObservability
        One record per estimated parameter, in :data:`CAMERA_PARAMETERS` order.
    max_correlation : Correlation or None
        The most correlated pair of observable parameters (None with fewer than two).
    eigenvalues : numpy.ndarray of float64, shape (E,)
        Eigenvalues of the data's information matrix over the estimated parameters, in
        prior-sigma units, ascending: near zero means a direction the data do not see.
    """

    params: tuple[ParamObservability, ...]
    max_correlation: Optional[Correlation]
    eigenvalues: _F64

    def __getitem__(self, name: str) -> ParamObservability:
        """The record of the estimated parameter ``name``; ``KeyError`` if not estimated."""
        for record in self.params:
            if record.name == name:
                return record
        raise KeyError(name)

    @property
    def unobservable(self) -> tuple[str, ...]:
        """Names of the estimated parameters the data cannot give."""
        return tuple(p.name for p in self.params if not p.observable)


@final
@dataclasses.dataclass(frozen=True, eq=False)
class Calibration:
    """The result of a phase-1 solve: the best estimate, its uncertainty, and the why.

    Attributes
    ----------
    camera : Camera
        The estimated camera parameters; parameters not estimated, or not observable, are at
        their nominal values.
    sigmas : dict of str to float
        1-sigma uncertainty of every parameter of :data:`CAMERA_PARAMETERS` (0 for those
        held fixed).
    covariance : numpy.ndarray of float64, shape (10, 10)
        Covariance of the ten parameters, rows and columns in :data:`CAMERA_PARAMETERS`
        order; zero rows for those held fixed.
    status : str
        ``"converged"``; ``"max_iterations"`` or ``"stalled"`` (the best estimate so far);
        ``"no_data"`` (no usable landmark pair: the start values).
    iterations : int
        Levenberg-Marquardt iterations taken.
    residuals : int
        Landmark residuals used (landmarks of frame pairs whose landmarks all triangulate).
    outliers : int
        Frame pairs beyond the Huber threshold at the solution (down-weighted).
    reduced_chi2 : float
        Chi-square at the solution over its degrees of freedom (about 1 when the noise model
        of the rig file is right).
    observability : Observability
        The observability analysis at the solution.
    history : numpy.ndarray of float64, shape (K, 10)
        The parameter vector at the start and after each accepted iteration.
    """

    camera: Camera
    sigmas: dict[str, float]
    covariance: _F64
    status: str
    iterations: int
    residuals: int
    outliers: int
    reduced_chi2: float
    observability: Observability
    history: _F64

    @property
    def converged(self) -> bool:
        """Whether the solve converged."""
        return self.status == "converged"


@final
@dataclasses.dataclass(frozen=True, eq=False)
class Handover:
    """What phase 1 hands to phase 2 once calibration is stable.

    Attributes
    ----------
    camera : Camera
        The calibrated camera parameters.
    sigmas : dict of str to float
        Their 1-sigma uncertainties (0 for those held fixed).
    covariance : numpy.ndarray of float64, shape (10, 10)
        Their covariance, in :data:`CAMERA_PARAMETERS` order.
    t_us : int
        Time of the frame at which calibration became stable.
    observability : Observability
        The observability analysis at hand-over.
    """

    camera: Camera
    sigmas: dict[str, float]
    covariance: _F64
    t_us: int
    observability: Observability


class CalibrationHistory(NamedTuple):
    """The camera parameters after each solve of a :class:`SelfCalibrator`, or of the
    incremental calibration of :func:`calibrate_log` (K solves)."""

    #: ``(K,)`` uint64: time of the last frame pair of each solve.
    t_us: _U64
    #: ``(K, 10)`` float64: the parameters, columns in :data:`CAMERA_PARAMETERS` order.
    values: _F64
    #: ``(K, 10)`` float64: their sigmas (0 for those held fixed).
    sigmas: _F64


@final
@dataclasses.dataclass(frozen=True, eq=False)
class LogCalibration:
    """Phase 1 on a whole vehicle log (:func:`calibrate_log`).

    Attributes
    ----------
    calibration : Calibration
        The batch solve over every frame pair of the log: the result.
    handover : Handover or None
        When the same pairs, fed one by one to a :class:`SelfCalibrator` with the stability
        rule given, made the calibration stable: the hand-over to phase 2 (its ``t_us`` is the
        time the vehicle would have switched). None when it never became stable.
    history : CalibrationHistory
        ``t_us``, ``values`` and ``sigmas`` after each incremental solve, up to the hand-over.
    counts : dict of str to int
        What was read, decoded, associated and paired: ``frames``, ``corrupt``, ``lost``,
        ``bytes_skipped``, ``frames_out_of_order``, ``odometry``, ``stereo_matches``,
        ``tracks``, ``confirmed_tracks``, ``pairs``, ``landmark_pairs``, ``tracker_resets``.
    warnings : tuple of str
        What limits the result without stopping it (a log cut short, a rig that differs
        from the log's ``/rig``, a solve that did not converge, a parameter held at its
        nominal value), one line each.
    rig_source : str
        ``"given"`` (the ``rig`` argument) or ``"log"`` (the log's ``/rig`` message).
    document : dict
        The whole result as ``stereonav calibrate --out RESULT.json`` writes it (the same
        function makes both): every parameter of ``C`` and ``V`` (``camera``, ``vehicle``:
        ``value``, ``sigma``, ``nominal``, ``estimated``), the solve, observability, the
        hand-over, the incremental history, counts and warnings. A new dict at each access.
    """

    calibration: Calibration
    handover: Optional[Handover]
    history: CalibrationHistory
    counts: dict[str, int]
    warnings: tuple[str, ...]
    rig_source: str
    _document_json: str = dataclasses.field(repr=False)

    @property
    def document(self) -> dict[str, Any]:
        """See the class docs."""
        document: dict[str, Any] = json.loads(self._document_json)
        return document


def _sigmas(covariance: _F64) -> dict[str, float]:
    diagonal = np.clip(np.diag(covariance), 0.0, None)
    return {name: float(math.sqrt(v)) for name, v in zip(CAMERA_PARAMETERS, diagonal)}


def _observability(native: _native.Observability) -> Observability:
    correlation = native.max_correlation
    return Observability(
        params=tuple(native.params),
        max_correlation=None if correlation is None else Correlation(*correlation),
        eigenvalues=_readonly(native.eigenvalues),
    )


def _calibration(native: _native.CalibrationResult) -> Calibration:
    """The typed result of a native solve (whatever made the frame pairs)."""
    covariance = _readonly(native.covariance)
    return Calibration(
        camera=Camera.from_array(native.camera),
        sigmas=_sigmas(covariance),
        covariance=covariance,
        status=native.status,
        iterations=native.iterations,
        residuals=native.residuals,
        outliers=native.outliers,
        reduced_chi2=native.reduced_chi2,
        observability=_observability(native.observability),
        history=_readonly(native.history),
    )


def _handover(native: Optional[_native.Handover]) -> Optional[Handover]:
    if native is None:
        return None
    return Handover(
        camera=Camera.from_array(native.camera),
        sigmas=_sigmas(native.covariance),
        covariance=_readonly(native.covariance),
        t_us=native.t_us,
        observability=_observability(native.observability),
    )


def _history(native: _native.CalibrationHistory, *, readonly: bool) -> CalibrationHistory:
    if readonly:
        return CalibrationHistory(
            t_us=_readonly(native.t_us),
            values=_readonly(native.values),
            sigmas=_readonly(native.sigmas),
        )
    return CalibrationHistory(t_us=native.t_us, values=native.values, sigmas=native.sigmas)


# --- Checking the arrays -------------------------------------------------------------------


def _structured(
    name: str, value: object, dtype: np.dtype[np.void], dtype_name: str
) -> npt.NDArray[np.void]:
    """``value`` if it is a 1-D structured array with every field of ``dtype``, else raise."""
    expected = ", ".join(dtype.names or ())
    if not isinstance(value, np.ndarray) or value.dtype.names is None:
        raise InputTypeError(
            f"{name} must be a NumPy structured array with fields {expected} "
            f"(numpy.zeros(n, stereonav.{dtype_name})), got {_describe(value)}"
        )
    for field in dtype.names or ():
        if field not in value.dtype.names:
            raise InputTypeError(
                f"{name} has no field {field!r} (it has {', '.join(value.dtype.names)}; "
                f"expected {expected})"
            )
    if value.ndim != 1:
        raise InputError(f"{name} has shape {value.shape}, expected a 1-D array (N,)")
    return value


def _describe(value: object) -> str:
    if isinstance(value, np.ndarray):
        return f"an array of dtype {value.dtype}"
    return type(value).__qualname__


def _floats(name: str, array: npt.NDArray[np.void], fields: tuple[str, ...]) -> _F64:
    """The float fields as one C-contiguous ``(N, len(fields))`` float64 array."""
    columns = []
    for field in fields:
        column = array[field]
        if column.dtype.kind not in "fiu" or column.ndim != 1:
            raise InputTypeError(
                f"{name} field {field!r} has dtype {column.dtype}, expected a real number "
                "(<f8)"
            )
        columns.append(column.astype(np.float64))
    if not columns:
        return np.zeros((len(array), 0), dtype=np.float64)
    return np.ascontiguousarray(np.column_stack(columns))


def _integers(name: str, array: npt.NDArray[np.void], field: str) -> _U64:
    """An unsigned integer field as a C-contiguous uint64 array; negative values refused."""
    column = array[field]
    if column.dtype.kind not in "iu" or column.ndim != 1:
        raise InputTypeError(
            f"{name} field {field!r} has dtype {column.dtype}, expected an unsigned integer"
        )
    if column.dtype.kind == "i" and len(column) and column.min() < 0:
        row = int(np.argmax(column < 0))
        raise InputError(f"{name}[{row}] {field} is {column[row]}, expected >= 0")
    return np.ascontiguousarray(column.astype(np.uint64))


def _observation_tables(observations: object) -> tuple[_U64, _F64]:
    array = _structured("observations", observations, OBSERVATION_DTYPE, "OBSERVATION_DTYPE")
    return _integers("observations", array, "pair"), _floats(
        "observations", array, _OBSERVATION_VALUES
    )


def _motion_tables(motions: object) -> tuple[_U64, _F64, _U64]:
    array = _structured("motions", motions, MOTION_DTYPE, "MOTION_DTYPE")
    return (
        _integers("motions", array, "t_us"),
        _floats("motions", array, _MOTION_VALUES),
        _integers("motions", array, "samples"),
    )


def _odometry_tables(odometry: object) -> tuple[_U64, _F64]:
    array = _structured("odometry", odometry, ODOMETRY_DTYPE, "ODOMETRY_DTYPE")
    return _integers("odometry", array, "t_us"), _floats("odometry", array, _ODOMETRY_VALUES)


def _times(name: str, value: object) -> _U64:
    array = np.asarray(value)
    if array.dtype.kind not in "iu":
        raise InputTypeError(f"{name} has dtype {array.dtype}, expected integer microseconds")
    if array.ndim != 1:
        raise InputError(f"{name} has shape {array.shape}, expected (N,)")
    if array.dtype.kind == "i" and len(array) and array.min() < 0:
        row = int(np.argmax(array < 0))
        raise InputError(f"{name}[{row}] is {array[row]}, expected >= 0")
    return np.ascontiguousarray(array.astype(np.uint64))


def _motions_array(t_us: _U64, values: _F64, samples: _U64) -> npt.NDArray[np.void]:
    out = np.zeros(len(t_us), dtype=MOTION_DTYPE)
    out["t_us"] = t_us
    for k, field in enumerate(_MOTION_VALUES):
        out[field] = values[:, k]
    out["samples"] = np.minimum(samples, _U32_MAX)
    return out


def _rig(rig: object) -> _native.Rig:
    """The native rig of a :class:`RigConfig` or a rig file's path (errors name it)."""
    if not isinstance(rig, (str, os.PathLike, RigConfig)):
        raise InputTypeError(
            f"rig must be a stereonav.RigConfig or the path of a rig file, got {_describe(rig)}"
        )
    return _native_rig(rig)


def _number(name: str, value: object) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputTypeError(f"{name} must be a number, got {_describe(value)} {value!r}")
    return float(value)


def _count(name: str, value: object, low: int) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise InputTypeError(f"{name} must be an int, got {_describe(value)} {value!r}")
    number = int(value)
    if number < low or number > (1 << 63) - 1:
        raise InputError(f"{name} is {number}, expected an integer >= {low}")
    return number


def _settings(
    huber: object, max_iterations: object, step_tolerance: object, observable_ratio: object
) -> _native.SolverSettings:
    return _native.SolverSettings(
        huber=_number("huber", huber),
        max_iterations=_count("max_iterations", max_iterations, 0),
        step_tolerance=_number("step_tolerance", step_tolerance),
        observable_ratio=_number("observable_ratio", observable_ratio),
    )


def _rule(
    min_pairs: object,
    sigma_fraction: object,
    step_fraction: object,
    consecutive: object,
    solve_every: object,
) -> _native.StableRule:
    return _native.StableRule(
        min_pairs=_count("min_pairs", min_pairs, 0),
        sigma_fraction=_number("sigma_fraction", sigma_fraction),
        step_fraction=_number("step_fraction", step_fraction),
        consecutive=_count("consecutive", consecutive, 1),
        solve_every=_count("solve_every", solve_every, 1),
    )


# --- Building frame pairs ------------------------------------------------------------------


def integrate_odometry(
    odometry: npt.NDArray[np.void], t0_us: npt.ArrayLike, t1_us: npt.ArrayLike
) -> npt.NDArray[np.void]:
    """The robot's motion over each time span, from the odometry (``vehicle-interfaces.md``
    section 2: each velocity sample held from its timestamp until the next).

    Parameters
    ----------
    odometry : numpy.ndarray of ODOMETRY_DTYPE, shape (S,)
        ``t_us`` (sorted), ``vx``, ``vy`` (m/s), ``vtheta`` (rad/s), as
        :attr:`Simulation.odometry <stereonav.Simulation>`.
    t0_us, t1_us : array_like of int, shape (P,)
        Start and end of each span, microseconds, ``t0_us <= t1_us``.

    Returns
    -------
    numpy.ndarray of MOTION_DTYPE, shape (P,)
        The motion of each span in the robot frame at its start; ``t_us`` is ``t1_us``.

    Raises
    ------
    InputTypeError
        (a ``TypeError``) ``odometry`` is not a structured array with the odometry fields, or
        a field or time array has a non-numeric dtype.
    InputError
        (a ``ValueError``) unsorted or non-finite odometry (the row is named), a span that
        ends before it starts, or one that starts before the first odometry sample.
    """
    t_us, values = _odometry_tables(odometry)
    t0, t1 = _times("t0_us", t0_us), _times("t1_us", t1_us)
    if t0.shape != t1.shape:
        raise InputError(f"t0_us has shape {t0.shape} but t1_us {t1.shape}: expected the same")
    motion, samples = _native.integrate_odometry((t_us, values), t0, t1)
    return _motions_array(t1, motion, samples)


def frame_pairs(
    measurements: npt.NDArray[np.void], odometry: npt.NDArray[np.void], *, stride: int = 1
) -> tuple[npt.NDArray[np.void], npt.NDArray[np.void]]:
    """Frame pairs from per-frame measurements with landmark ids and the odometry.

    The frames are the distinct ``t_us`` of ``measurements``, in time order. The pairs are
    disjoint, ``stride`` frames apart (frames ``(0, stride)``, ``(stride + 1, 2 stride + 1)``,
    ...), so that no frame's noise counts in two pairs. Each pair gets the odometry integrated
    between its two frames (:func:`integrate_odometry`) and every landmark id seen in both
    frames, in id order. Pairs whose first frame comes before the first odometry sample are
    left out.

    Parameters
    ----------
    measurements : numpy.ndarray of MEASUREMENT_DTYPE, shape (N,)
        ``t_us``, landmark ``id``, ``uL, vL, uR, vR`` (pixels); each id at most once a frame.
    odometry : numpy.ndarray of ODOMETRY_DTYPE, shape (S,)
        Velocity samples sorted by ``t_us``.
    stride : int, keyword-only
        Frames from the first frame of a pair to its second (1: consecutive frames). Longer
        pairs see more motion per pixel of noise.

    Returns
    -------
    observations : numpy.ndarray of OBSERVATION_DTYPE, shape (M,)
    motions : numpy.ndarray of MOTION_DTYPE, shape (P,)
        The frame pairs, ready for :func:`calibrate` or :meth:`SelfCalibrator.add_pairs`.

    Raises
    ------
    InputTypeError
        (a ``TypeError``) an argument is not a structured array with the fields above, or
        ``stride`` is not an int.
    InputError
        (a ``ValueError``) a non-finite value, a repeated id in a frame, unsorted odometry
        (the row and field are named), or ``stride < 1``.
    """
    table = _structured("measurements", measurements, MEASUREMENT_DTYPE, "MEASUREMENT_DTYPE")
    columns = (
        _integers("measurements", table, "t_us"),
        _integers("measurements", table, "id"),
        _floats("measurements", table, _MEASUREMENT_VALUES),
    )
    odometry_columns = _odometry_tables(odometry)
    (pair, values), (t_us, motion, samples) = _native.frame_pairs(
        columns, odometry_columns, _count("stride", stride, 1)
    )
    observations = np.zeros(len(pair), dtype=OBSERVATION_DTYPE)
    observations["pair"] = pair
    for k, field in enumerate(_OBSERVATION_VALUES):
        observations[field] = values[:, k]
    return observations, _motions_array(t_us, motion, samples)


# --- Solving -------------------------------------------------------------------------------

#: A rig: a :class:`RigConfig` or the path of a rig file.
RigLike = Union[RigConfig, str, "os.PathLike[str]"]


def calibrate(
    observations: npt.NDArray[np.void],
    motions: npt.NDArray[np.void],
    rig: RigLike,
    *,
    start: Optional[Union[Camera, npt.ArrayLike]] = None,
    huber: float = _SOLVER.huber,
    max_iterations: int = _SOLVER.max_iterations,
    step_tolerance: float = _SOLVER.step_tolerance,
    observable_ratio: float = _SOLVER.observable_ratio,
) -> Calibration:
    """Calibrate the rig's estimated camera parameters from frame pairs (phase 1, batch).

    Solves eq. (2) by Levenberg-Marquardt on the mismatch of eq. (1) over every landmark of
    every pair, each pair's landmarks whitened jointly by the pixel and odometry noise of the
    rig file, with a Huber loss against wrong associations and the rig's priors. Parameters
    the data cannot constrain are held at their nominal values and reported with the reason
    in :attr:`Calibration.observability`. Never fails on data: without usable pairs the
    status is ``"no_data"``; a solve that runs out of iterations returns its best estimate.
    The GIL is released while solving.

    Parameters
    ----------
    observations : numpy.ndarray of OBSERVATION_DTYPE, shape (N,)
        Landmarks seen at both frames of a pair: ``pair`` (row of ``motions``), ``uL0 ..
        vR0`` at the first frame, ``uL1 .. vR1`` at the second, pixels. Other integer and
        float dtypes of the fields are converted; extra fields are ignored.
    motions : numpy.ndarray of MOTION_DTYPE, shape (P,)
        One row per pair: ``t_us``, ``dx``, ``dy``, ``dtheta``, ``dt_s``, ``samples``
        (:func:`integrate_odometry` or :func:`frame_pairs` make them).
    rig : RigConfig or path
        The rig file (:func:`stereonav.load_rig`), or its path: nominal camera, which
        parameters to estimate, their priors, the noise model.
    start : Camera or array_like of 10 floats, optional, keyword-only
        Where the solve starts (default: the rig's nominal camera).
    huber : float, keyword-only
        Huber threshold on a landmark's Mahalanobis norm (grown with a pair's landmarks).
    max_iterations : int, keyword-only
        Most Levenberg-Marquardt iterations.
    step_tolerance : float, keyword-only
        Converged when every step is below this fraction of the parameter's sigma.
    observable_ratio : float, keyword-only
        A parameter is observable when the data bring its sigma to at most this fraction of
        its prior sigma, in ``(0, 1]``.

    Returns
    -------
    Calibration

    Raises
    ------
    InputTypeError
        (a ``TypeError``) an array is not a structured array, lacks a field (named) or has a
        field of a non-numeric dtype; a keyword has the wrong type.
    InputError
        (a ``ValueError``) a NaN or infinite value (the array, row and field are named), a
        ``pair`` beyond the rows of ``motions``, a negative ``dt_s``, a bad rig, start camera
        or setting.
    """
    pair, values = _observation_tables(observations)
    motion_tables = _motion_tables(motions)
    native_rig = _rig(rig)
    start_array = None if start is None else _camera(start)
    settings = _settings(huber, max_iterations, step_tolerance, observable_ratio)
    native = _native.calibrate(native_rig, (pair, values), motion_tables, start_array, settings)
    return _calibration(native)


def calibrate_log(
    log_path: Union[str, "os.PathLike[str]"],
    rig: Optional[RigLike] = None,
    *,
    stride: int = _PAIRS.stride,
    pairing: str = _PAIRS.pairing,
    huber: float = _SOLVER.huber,
    max_iterations: int = _SOLVER.max_iterations,
    step_tolerance: float = _SOLVER.step_tolerance,
    observable_ratio: float = _SOLVER.observable_ratio,
    solve_every: int = _RULE.solve_every,
    min_pairs: int = _RULE.min_pairs,
    sigma_fraction: float = _RULE.sigma_fraction,
    step_fraction: float = _RULE.step_fraction,
    consecutive: int = _RULE.consecutive,
) -> LogCalibration:
    """Phase 1 on a vehicle log: calibrate the rig's estimated camera parameters in batch.

    The whole chain runs in Rust with the GIL released, as the vehicle would run it: the log
    (MCAP, ``vehicle-interfaces.md`` section 4) is read, the board's byte stream decoded
    (corrupt packets and lost frames are counted, never fatal), frames and odometry ordered
    by their timestamps, the landmarks matched left to right and tracked with the odometry,
    and frame pairs ``stride`` frames apart built from the confirmed tracks. They are solved
    once in batch (the result, as :func:`calibrate`), and fed one by one to a
    :class:`SelfCalibrator` to find when the estimate became stable (the hand-over time).

    Parameters
    ----------
    log_path : str or os.PathLike
        The vehicle log.
    rig : RigConfig or path, optional
        The rig file (:func:`stereonav.load_rig`) or its path; default: the log's ``/rig``
        message. A rig that differs from the log's is used, with a warning.
    stride : int, keyword-only
        Frames from the first frame of a pair to its second, ``1..=1000000`` (40 frames are
        2 s at 20 Hz: more motion per pixel of noise).
    pairing : str, keyword-only
        ``"disjoint"``: pairs ``(0, s)``, ``(s + 1, 2 s + 1)``, ... (no frame in two pairs);
        ``"interleaved"``: ``(k, k + s)`` for ``k`` in each block ``[2 j s, 2 j s + s)``
        (every frame in exactly one pair).
    huber, max_iterations, step_tolerance, observable_ratio : keyword-only
        The solver settings, as in :func:`calibrate`.
    solve_every, min_pairs, sigma_fraction, step_fraction, consecutive : keyword-only
        The incremental calibration and its stability rule, as in :class:`SelfCalibrator`.

    Returns
    -------
    LogCalibration

    Raises
    ------
    InputTypeError
        (a ``TypeError``) an argument has the wrong type.
    InputError
        (a ``ValueError``) the log cannot be read (missing or unreadable file: the message
        names it, and the ``OSError`` is the ``__cause__``), is not an MCAP file, is an MCAP
        file without the vehicle topics, or has a malformed vehicle message; there is no rig
        (none given and no ``/rig`` in the log) or it is not valid; a setting is out of
        range. A log cut short is not an error: see :attr:`LogCalibration.warnings`.
    """
    if not isinstance(log_path, (str, os.PathLike)):
        raise InputTypeError(f"log_path must be a str or os.PathLike, got {_describe(log_path)}")
    path = os.fspath(log_path)
    if not isinstance(path, str):
        raise InputTypeError(f"log_path must be a str path, got {_describe(path)}")
    native_rig = None if rig is None else _rig(rig)
    if not isinstance(pairing, str):
        raise InputTypeError(
            f"pairing must be a str ({' or '.join(map(repr, _PAIRINGS))}), got {_describe(pairing)}"
        )
    pairs = _native.PairSettings(stride=_count("stride", stride, 1), pairing=pairing)
    settings = _settings(huber, max_iterations, step_tolerance, observable_ratio)
    rule = _rule(min_pairs, sigma_fraction, step_fraction, consecutive, solve_every)
    native = _native.calibrate_log(path, native_rig, pairs, settings, rule)
    return LogCalibration(
        calibration=_calibration(native.calibration),
        handover=_handover(native.handover),
        history=_history(native.history, readonly=True),
        counts=dict(native.counts),
        warnings=tuple(native.warnings),
        rig_source=native.rig_source,
        _document_json=native.document_json(),
    )


@final
class SelfCalibrator:
    """Phase 1 fed pair by pair, until calibration is stable and hands over to phase 2.

    Frame pairs are collected; every ``solve_every`` pairs all of them are solved again,
    warm-started from the last estimate. Calibration is stable when, for ``consecutive``
    solves in a row with at least ``min_pairs`` pairs, every observable estimated parameter
    moved less than ``step_fraction`` of its sigma since the previous solve and its sigma is
    at most ``sigma_fraction`` of its prior sigma, and no estimated parameter is still waiting
    for data (see :attr:`ParamObservability.structural`); then :attr:`handover` holds the
    camera parameters and their covariance for phase 2.

    Parameters
    ----------
    rig : RigConfig or path
        The rig file, or its path.
    solve_every : int, keyword-only
        Pairs between two solves.
    min_pairs, sigma_fraction, step_fraction, consecutive : keyword-only
        The stability rule (above).
    huber, max_iterations, step_tolerance, observable_ratio : keyword-only
        The solver settings, as in :func:`calibrate`.

    Raises
    ------
    InputTypeError, InputError
        A bad rig or setting.
    """

    def __init__(
        self,
        rig: RigLike,
        *,
        solve_every: int = _RULE.solve_every,
        min_pairs: int = _RULE.min_pairs,
        sigma_fraction: float = _RULE.sigma_fraction,
        step_fraction: float = _RULE.step_fraction,
        consecutive: int = _RULE.consecutive,
        huber: float = _SOLVER.huber,
        max_iterations: int = _SOLVER.max_iterations,
        step_tolerance: float = _SOLVER.step_tolerance,
        observable_ratio: float = _SOLVER.observable_ratio,
    ) -> None:
        native_rig = _rig(rig)
        rule = _rule(min_pairs, sigma_fraction, step_fraction, consecutive, solve_every)
        settings = _settings(huber, max_iterations, step_tolerance, observable_ratio)
        self._native = _native.SelfCalibrator(native_rig, settings, rule)

    def add_pairs(self, observations: npt.NDArray[np.void], motions: npt.NDArray[np.void]) -> int:
        """Add frame pairs in the array form of :func:`calibrate`, in the order of ``motions``.

        Returns the number of solves they triggered. Nothing is added when an array is bad
        (the exceptions of :func:`calibrate`). The GIL is released while solving.
        """
        pair, values = _observation_tables(observations)
        return self._native.add_pairs((pair, values), _motion_tables(motions))

    def add_pair(
        self, observations: npt.NDArray[np.void], motion: Union[npt.NDArray[np.void], np.void]
    ) -> Optional[Calibration]:
        """Add one frame pair; return the new :class:`Calibration` when it triggered a solve.

        Parameters
        ----------
        observations : numpy.ndarray of OBSERVATION_DTYPE, shape (K,)
            The pair's landmarks; the ``pair`` field is ignored (every row is this pair's).
        motion : numpy.ndarray of MOTION_DTYPE, shape () or (1,)
            The pair's motion (one record, e.g. ``motions[i]`` or ``motions[i:i + 1]``).
        """
        record = np.atleast_1d(motion) if isinstance(motion, (np.ndarray, np.void)) else motion
        table = _structured("motion", record, MOTION_DTYPE, "MOTION_DTYPE")
        if len(table) != 1:
            raise InputError(f"motion has {len(table)} rows, expected one record (one pair)")
        _, values = _observation_tables(observations)
        pair = np.zeros(len(values), dtype=np.uint64)
        solves = self._native.add_pairs((pair, values), _motion_tables(table))
        return self.latest if solves else None

    @property
    def latest(self) -> Optional[Calibration]:
        """The latest solve, or None before the first."""
        native = self._native.latest
        return None if native is None else _calibration(native)

    @property
    def handover(self) -> Optional[Handover]:
        """The hand-over to phase 2 once calibration is stable, else None."""
        return _handover(self._native.handover)

    @property
    def history(self) -> CalibrationHistory:
        """The camera parameters and sigmas after each solve."""
        return _history(self._native.history, readonly=False)

    @property
    def pairs(self) -> int:
        """Frame pairs collected so far."""
        return self._native.pairs
