"""Phase 2 of the method: EKF SLAM with the camera parameters in the state (eq. 3-8).

The state is ``x = [X, Y, theta, L_1, ..., L_N, C_est]``: the planar robot pose, the world
point of every landmark (ceiling lamp) in the map, then the camera parameters the rig file
estimates, in its ``estimate`` order. The covariance is dense, ``n x n`` with
``n = 3 + 3 N + m``. The world frame is the robot at the start: the filter starts at the
origin with zero pose covariance, and the camera from phase 1's :class:`Handover` (or, when
phase 1 is skipped, from the rig's nominal values and prior sigmas).

A :class:`Filter` is stepped frame by frame:

- :meth:`Filter.predict_odometry` (or :meth:`Filter.predict`) moves the pose with the
  odometry between two frames (eq. 4-5);
- :meth:`Filter.observe` takes the frame's stereo measurements keyed by the association's
  track ids: tracks bound to a landmark update the filter (eq. 6-8), each observation gated
  on its own normalised innovation squared (NIS); an unbound track becomes a landmark after
  ``frames_to_confirm`` consecutive frames whose triangulations agree;
- or, by landmark id, :meth:`Filter.update` and :meth:`Filter.add_landmark` directly.

Everything runs in Rust (crate ``vslam-ekf``) with the GIL released; arrays come back as
copies. :func:`stereonav.monte_carlo` evaluates the filter over many seeded simulations.
"""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple, Optional, final

import numpy as np
import numpy.typing as npt

from . import _native
from ._arrays import BINDING_DTYPE, GATE_DTYPE
from ._arrays import bindings as _bindings
from ._arrays import gated as _gated
from ._arrays import readonly as _readonly
from ._errors import InputError, InputTypeError
from .calibration import (
    Handover,
    RigLike,
    _count,
    _describe,
    _number,
    _odometry_tables,
    _rig,
)
from .rig import Camera

__all__ = [
    "BINDING_DTYPE",
    "COVARIANCE_UPDATES",
    "GATE_DTYPE",
    "LANDMARK_DTYPE",
    "Filter",
    "FrameReport",
    "Health",
    "PredictedMeasurement",
    "UpdateReport",
]

#: One landmark of the map: ``id`` (``<u8``), its world position ``x, y, z`` (``<f8``,
#: metres), its position ``covariance`` (``<f8``, shape (3, 3), m**2) and ``observations``
#: (``<u8``: the measurement that created it and every accepted one since). The 1-sigma
#: per axis is ``np.sqrt(np.diagonal(landmarks["covariance"], axis1=1, axis2=2))``.
LANDMARK_DTYPE = np.dtype(
    [
        ("id", "<u8"),
        ("x", "<f8"),
        ("y", "<f8"),
        ("z", "<f8"),
        ("covariance", "<f8", (3, 3)),
        ("observations", "<u8"),
    ]
)
#: The forms of the covariance update (crate ``vslam-ekf``): ``"joseph"``
#: (``P - K A^T - A K^T + K S K^T``, insensitive to first order to errors of the gain),
#: ``"factored"`` (``P - W W^T``, ``W = P H^T L^-T``, ``S = L L^T``: half the work) and
#: ``"auto"`` (Joseph up to 400 states, factored above: the default).
COVARIANCE_UPDATES: tuple[str, ...] = ("auto", "joseph", "factored")

# The keyword defaults are the Rust ``Default``s (``vslam_ekf::Settings``,
# ``CandidateSettings``), read from the native settings made without keywords.
_DEFAULTS = _native.FilterSettings()

_F64 = npt.NDArray[np.float64]
_U64 = npt.NDArray[np.uint64]
_U64_MAX = (1 << 64) - 1


# --- Results -------------------------------------------------------------------------------


@final
@dataclasses.dataclass(frozen=True, eq=False)
class UpdateReport:
    """What one update did.

    Attributes
    ----------
    accepted : numpy.ndarray of GATE_DTYPE, shape (A,)
        Observations the gate let through (and that were applied), with their NIS, in the
        order given.
    rejected : numpy.ndarray of GATE_DTYPE, shape (R,)
        Observations the gate left out, with their NIS (above :attr:`Filter.gate_bound`).
    removed : numpy.ndarray of uint64, shape (D,)
        Landmarks removed after this update as false: rejected ``max_consecutive_rejections``
        times in a row.
    """

    accepted: npt.NDArray[np.void]
    rejected: npt.NDArray[np.void]
    removed: _U64


@final
@dataclasses.dataclass(frozen=True, eq=False)
class FrameReport:
    """What one frame of :meth:`Filter.observe` did.

    Attributes
    ----------
    update : UpdateReport
        The update with the tracks bound to landmarks (ids in it are landmark ids).
    added : numpy.ndarray of BINDING_DTYPE, shape (K,)
        Tracks confirmed this frame and the landmarks made of them.
    removed : numpy.ndarray of BINDING_DTYPE, shape (K,)
        Landmarks removed as false this frame, with their tracks (now retired: their
        measurements are ignored from now on).
    ignored : int
        Measurements of retired tracks, ignored.
    pending : int
        Candidates still waiting for confirmation.
    """

    update: UpdateReport
    added: npt.NDArray[np.void]
    removed: npt.NDArray[np.void]
    ignored: int
    pending: int


@final
@dataclasses.dataclass(frozen=True)
class Health:
    """The filter's health: counters, the NIS over a sliding window, a divergence flag.

    A consistent filter's accepted NIS is chi-square with 4 dof, so the window's mean per
    degree of freedom is near 1; above ``window_nis_bound`` (its 99.9 % chi-square bound)
    the filter is overconfident or its model is wrong.

    Attributes
    ----------
    updates : int
        Updates applied (batches with at least one observation, accepted or not).
    refused_updates : int
        Updates refused because the covariance lost positive definiteness or the result
        was not finite (the state was left as it was).
    accepted, rejected : int
        Landmark observations accepted and rejected by the gate, in all.
    landmarks_added, landmarks_removed : int
        Landmarks added and removed (as false, or on request), in all.
    window_observations : int
        Gate outcomes in the window (at most ``nis_window``).
    window_rejected : int
        Rejections among them.
    window_mean_nis_per_dof : float or None
        Mean NIS per degree of freedom of the accepted observations in the window (None
        while there are none).
    window_nis_bound : float or None
        That mean's 99.9 % bound for that many observations.
    nis_too_high : bool
        The window mean is above its bound.
    diverged : bool
        ``nis_too_high``, or an update was ever refused.
    """

    updates: int
    refused_updates: int
    accepted: int
    rejected: int
    landmarks_added: int
    landmarks_removed: int
    window_observations: int
    window_rejected: int
    window_mean_nis_per_dof: Optional[float]
    window_nis_bound: Optional[float]
    nis_too_high: bool
    diverged: bool


def _health(native: _native.Health) -> Health:
    """The :class:`Health` of the native one, field by field by name."""
    return Health(**{f.name: getattr(native, f.name) for f in dataclasses.fields(Health)})


class PredictedMeasurement(NamedTuple):
    """A landmark's predicted measurement at the current estimate (:meth:`Filter.predict_measurement`)."""

    #: ``(4,)`` float64: ``uL, vL, uR, vR`` in pixels.
    z: _F64
    #: ``(4, 4)`` float64: the innovation covariance ``S = H P H^T + R``.
    covariance: _F64


def _update_report(raw: _native._UpdateTuple) -> UpdateReport:
    accepted_ids, accepted_nis, rejected_ids, rejected_nis, removed = raw
    return UpdateReport(
        accepted=_gated(accepted_ids, accepted_nis),
        rejected=_gated(rejected_ids, rejected_nis),
        removed=_readonly(removed),
    )


# --- Checking the arguments ----------------------------------------------------------------


def _id(name: str, value: object) -> int:
    """An id: an integer in ``0..2**64``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise InputTypeError(f"{name} must be an int, got {_describe(value)} {value!r}")
    number = int(value)
    if not 0 <= number <= _U64_MAX:
        raise InputError(f"{name} is {number}, expected an integer in 0..2**64")
    return number


def _ids(name: str, value: object) -> _U64:
    """Ids as a C-contiguous uint64 ``(M,)`` array; negative values refused."""
    array = np.asarray(value)
    if array.size == 0 and array.dtype.kind == "f":
        array = array.astype(np.uint64)  # an empty list: no ids
    if array.dtype.kind not in "iu":
        raise InputTypeError(f"{name} has dtype {array.dtype}, expected unsigned integer ids (uint64)")
    if array.ndim != 1:
        raise InputError(f"{name} has shape {array.shape}, expected (M,)")
    if array.dtype.kind == "i" and array.size and array.min() < 0:
        row = int(np.argmax(array < 0))
        raise InputError(f"{name}[{row}] is {array[row]}, expected an id >= 0")
    return np.ascontiguousarray(array, dtype=np.uint64)


def _pixels(value: object, shape: tuple[int, ...]) -> _F64:
    """``z`` as a C-contiguous float64 array of ``shape`` (finite values checked natively)."""
    array = np.asarray(value)
    if array.dtype.kind not in "fiu":
        raise InputTypeError(f"z has dtype {array.dtype}, expected pixels as float64")
    if array.size == 0 and len(shape) == 2 and shape[0] == 0:
        array = array.reshape(0, 4)
    if array.shape != shape:
        expected = "(4,) = (uL, vL, uR, vR)" if len(shape) == 1 else f"({shape[0]}, 4): one row uL, vL, uR, vR per id"
        raise InputError(f"z has shape {array.shape}, expected {expected}")
    return np.ascontiguousarray(array, dtype=np.float64)


def _probability(name: str, value: object) -> float:
    number = _number(name, value)
    if not 0.0 < number < 1.0:
        raise InputError(f"{name} is {number}, expected a probability strictly between 0 and 1")
    return number


def _start(handover: object) -> Optional[tuple[_F64, _F64]]:
    if handover is None:
        return None
    if not isinstance(handover, Handover):
        raise InputTypeError(
            f"handover must be a stereonav.Handover (phase 1's result) or None, got {_describe(handover)}"
        )
    covariance = np.ascontiguousarray(handover.covariance, dtype=np.float64)
    return handover.camera.to_array(), covariance


# --- The filter ----------------------------------------------------------------------------


@final
class Filter:
    """Phase 2: EKF SLAM with the camera parameters in the state (eq. 3-8).

    Parameters
    ----------
    rig : RigConfig or path
        The rig file (:func:`stereonav.load_rig`) or its path: image size, nominal camera,
        which parameters to estimate, their priors, the noise model.
    handover : Handover, optional
        Phase 1's hand-over (:attr:`SelfCalibrator.handover`, :attr:`LogCalibration.handover`):
        the filter starts from its camera and covariance; an estimated parameter phase 1 held
        at nominal (zero variance) enters with the rig's prior variance. Default: the rig's
        nominal camera with its prior sigmas (phase 1 skipped).
    gate_probability : float, keyword-only
        Probability mass inside each observation's innovation gate (4 dof), in ``(0, 1)``;
        0.999 gives the NIS bound 18.47.
    nis_window : int, keyword-only
        Gate outcomes kept for :attr:`health`'s NIS statistics, at least 1.
    max_consecutive_rejections : int, keyword-only
        A landmark rejected this many times in a row is removed as false, at least 1.
    covariance_update : str, keyword-only
        Form of the covariance update, one of :data:`COVARIANCE_UPDATES` (both are exact;
        ``"auto"`` picks the faster one that is safe at the state's size).
    frames_to_confirm : int, keyword-only
        Consecutive frames with consistent triangulations before :meth:`observe` makes a
        track a landmark, at least 1.
    consistency_probability : float, keyword-only
        Probability mass inside the consistency gate between a candidate's successive world
        points (3 dof), in ``(0, 1)``.

    Raises
    ------
    InputTypeError
        (a ``TypeError``) an argument has the wrong type.
    InputError
        (a ``ValueError``) a bad rig (a parameter estimated without a prior), a hand-over
        covariance that is not positive definite, or a setting out of range.
    """

    def __init__(
        self,
        rig: RigLike,
        handover: Optional[Handover] = None,
        *,
        gate_probability: float = _DEFAULTS.gate_probability,
        nis_window: int = _DEFAULTS.nis_window,
        max_consecutive_rejections: int = _DEFAULTS.max_consecutive_rejections,
        covariance_update: str = _DEFAULTS.covariance_update,
        frames_to_confirm: int = _DEFAULTS.frames_to_confirm,
        consistency_probability: float = _DEFAULTS.consistency_probability,
    ) -> None:
        native_rig = _rig(rig)
        settings = _native.FilterSettings(
            gate_probability=_probability("gate_probability", gate_probability),
            nis_window=_count("nis_window", nis_window, 1),
            max_consecutive_rejections=_small_count(
                "max_consecutive_rejections", max_consecutive_rejections
            ),
            covariance_update=_form(covariance_update),
            frames_to_confirm=_small_count("frames_to_confirm", frames_to_confirm),
            consistency_probability=_probability("consistency_probability", consistency_probability),
        )
        self._native = _native.Filter(native_rig, _start(handover), settings)

    @classmethod
    def _wrap(cls, native: _native.Filter) -> Filter:
        filter_ = cls.__new__(cls)
        filter_._native = native
        return filter_

    def copy(self) -> Filter:
        """An independent copy: state, covariance, landmarks, track bindings, health.

        The copy and the original evolve separately from here on (e.g. to try a step two
        ways, or to time one update repeatedly). The GIL is released while copying.
        """
        return Filter._wrap(self._native.copy())

    def __copy__(self) -> Filter:
        """:meth:`copy` (the filter owns no Python objects, so shallow and deep agree)."""
        return self.copy()

    def __deepcopy__(self, memo: dict[int, Any]) -> Filter:
        """:meth:`copy`."""
        return self.copy()

    def __repr__(self) -> str:
        x, y, theta = self.pose
        return (
            f"<stereonav.Filter: {len(self.state)} states, {len(self.landmarks)} landmarks, "
            f"pose ({x:.3f} m, {y:.3f} m, {theta:.4f} rad)>"
        )

    # --- Stepping ------------------------------------------------------------------------

    def predict(self, vx: float, vy: float, vtheta: float, dt: float) -> None:
        """Eq. 3-4: move the pose with robot-frame velocities held for ``dt`` seconds.

        The pose moves along the exact arc; its covariance grows by the rig's velocity and
        yaw-rate noise (white, one sample). Only the pose rows and columns change.

        Parameters
        ----------
        vx, vy : float
            Velocities in the robot frame, m/s.
        vtheta : float
            Yaw rate, rad/s.
        dt : float
            Time held, seconds, ``>= 0``.

        Raises
        ------
        InputTypeError
            A value is not a number.
        InputError
            A value is not finite, or ``dt`` is negative.
        """
        self._native.predict(
            _number("vx", vx), _number("vy", vy), _number("vtheta", vtheta), _number("dt", dt)
        )

    def predict_odometry(self, odometry: npt.NDArray[np.void], t0_us: int, t1_us: int) -> None:
        """Eq. 3-4 over ``[t0_us, t1_us]``: the odometry samples composed into one motion.

        Each sample's velocities are held from its timestamp until the next (as phase 1
        integrates them), the pieces composed with their covariance, and applied once.

        Parameters
        ----------
        odometry : numpy.ndarray of ODOMETRY_DTYPE, shape (S,)
            ``t_us`` (sorted), ``vx``, ``vy`` (m/s), ``vtheta`` (rad/s), as
            :attr:`Simulation.odometry <stereonav.Simulation>`; only the samples that cover
            the interval matter.
        t0_us, t1_us : int
            The interval, microseconds (the previous frame's time and this one's).

        Raises
        ------
        InputTypeError
            ``odometry`` is not a structured array with the odometry fields; a time is not
            an int.
        InputError
            Unsorted or non-finite odometry (the row is named), ``t1_us < t0_us``, or no
            sample at or before ``t0_us``.
        """
        tables = _odometry_tables(odometry)
        self._native.predict_odometry(tables, _count("t0_us", t0_us, 0), _count("t1_us", t1_us, 0))

    def update(self, ids: npt.ArrayLike, z: npt.ArrayLike) -> UpdateReport:
        """Eq. 5-8: update with measurements of landmarks in the map.

        Every observation is linearised at the current estimate and gated on its own NIS
        (its 4x4 block of ``S``) against :attr:`gate_bound`; the accepted ones are applied
        together. A landmark rejected ``max_consecutive_rejections`` times in a row is
        removed as false.

        Parameters
        ----------
        ids : array_like of int, shape (M,)
            Landmark ids (:meth:`add_landmark`, :attr:`landmarks`), each at most once.
        z : array_like of float, shape (M, 4)
            Their measurements ``uL, vL, uR, vR``, pixels.

        Returns
        -------
        UpdateReport

        Raises
        ------
        InputTypeError
            Ids that are not integers, or ``z`` not numeric.
        InputError
            A shape that does not match, a non-finite pixel (row and field named), an id not
            in the map or repeated. Nothing changes.
        Error
            The filter refused the update: the innovation covariance or a variance lost
            positive definiteness, or the state would not be finite. Nothing changes (the
            refusal is counted in :attr:`health`).
        """
        checked_ids = _ids("ids", ids)
        return _update_report(self._native.update(checked_ids, _pixels(z, (len(checked_ids), 4))))

    def observe(self, tracks: npt.ArrayLike, z: npt.ArrayLike) -> FrameReport:
        """One stereo frame keyed by the association's track ids (call after predicting to it).

        Tracks bound to a landmark update the filter as :meth:`update`; a landmark removed as
        false retires its track (its measurements are ignored from then on). An unbound
        track is a candidate: it becomes a landmark once seen in ``frames_to_confirm``
        consecutive frames whose triangulations agree within the consistency gate (so
        clutter never enters the map); a candidate missing from a frame starts again.

        Parameters
        ----------
        tracks : array_like of int, shape (M,)
            Track ids, each at most once.
        z : array_like of float, shape (M, 4)
            Their measurements ``uL, vL, uR, vR``, pixels.

        Returns
        -------
        FrameReport

        Raises
        ------
        InputTypeError, InputError, Error
            As :meth:`update` (a repeated track is an :class:`InputError`). Nothing changes.
        """
        checked = _ids("tracks", tracks)
        raw = self._native.observe(checked, _pixels(z, (len(checked), 4)))
        update, added, removed, ignored, pending = raw
        return FrameReport(
            update=_update_report(update),
            added=_readonly(_bindings(added)),
            removed=_readonly(_bindings(removed)),
            ignored=ignored,
            pending=pending,
        )

    def add_landmark(self, z: npt.ArrayLike) -> int:
        """Add a landmark triangulated from one measurement at the current pose and camera.

        Its covariance is the joint linearisation in the pose, the camera and the pixels,
        with its cross-covariances to every other state (so that a later update of the
        camera moves all the landmarks seen with it). Returns the new landmark's id (ids
        increase and are never reused).

        Parameters
        ----------
        z : array_like of float, shape (4,)
            ``uL, vL, uR, vR``, pixels.

        Raises
        ------
        InputTypeError
            ``z`` is not numeric.
        InputError
            A wrong shape, a non-finite pixel, or a measurement that cannot be triangulated
            (disparity ``uL - uR`` not positive).
        """
        return self._native.add_landmark(_pixels(z, (4,)))

    def remove_landmark(self, id: int) -> None:
        """Remove a landmark: its rows and columns leave the state; its track is unbound
        (and may confirm again). Raises :class:`InputError` for an id not in the map."""
        self._native.remove_landmark(_id("id", id))

    # --- Inspection ----------------------------------------------------------------------

    def predict_measurement(self, id: int) -> PredictedMeasurement:
        """A landmark's predicted measurement and innovation covariance ``S = H P H^T + R``,
        ``H`` from :meth:`prediction_jacobian`.

        For association and map matching: a measurement ``z`` is this landmark's when
        ``(z - p.z) @ inv(p.covariance) @ (z - p.z) <= gate_bound``.

        Raises
        ------
        InputError
            ``id`` is not in the map.
        Error
            The landmark cannot be projected at the current estimate (behind the cameras).
        """
        z, covariance = self._native.predict_measurement(_id("id", id))
        return PredictedMeasurement(z, covariance)

    def measurement_jacobian(self, id: int) -> tuple[_F64, _F64]:
        """``(z (4,), H (4, n))``: a landmark's predicted measurement and the dense Jacobian
        of ``uL, vL, uR, vR`` with respect to the whole state (non-zero only in the pose,
        the landmark's and the estimated camera columns). For tests and tools: the update
        itself never forms ``H``. Raises as :meth:`predict_measurement`."""
        return self._native.measurement_jacobian(_id("id", id))

    def prediction_jacobian(self, id: int) -> tuple[_F64, _F64]:
        """``(z (4,), H (4, n))``: the Jacobian :meth:`predict_measurement`'s ``S`` is formed
        with, dense: :meth:`measurement_jacobian`'s but for the heading's column (index 2),
        which comes from the observability constraint at the landmark's linearisation point
        (so that turning the whole world changes no prediction as the covariance has it;
        docs/vehicle.md, "Dark stretches"). Raises as :meth:`predict_measurement`."""
        return self._native.prediction_jacobian(_id("id", id))

    @property
    def state(self) -> _F64:
        """``(n,)`` float64: ``[X, Y, theta, L_1 (x, y, z), ..., L_N, C_est]`` (a copy)."""
        return self._native.state

    @property
    def covariance(self) -> _F64:
        """``(n, n)`` float64: the covariance of :attr:`state`, symmetric (a copy)."""
        return self._native.covariance

    @property
    def pose(self) -> _F64:
        """``(3,)`` float64: the robot pose ``(X, Y, theta)``, metres and radians,
        ``theta`` in ``(-pi, pi]``."""
        return self._native.pose

    @property
    def pose_covariance(self) -> _F64:
        """``(3, 3)`` float64: the covariance of :attr:`pose`."""
        return self._native.pose_covariance

    @property
    def camera(self) -> Camera:
        """Every camera parameter: the estimated ones from the state, the others fixed."""
        return Camera.from_array(self._native.camera)

    @property
    def camera_covariance(self) -> _F64:
        """``(10, 10)`` float64: the camera covariance in :data:`CAMERA_PARAMETERS` order,
        zero rows and columns for the parameters not estimated."""
        return self._native.camera_covariance

    @property
    def estimated_parameters(self) -> tuple[str, ...]:
        """Names of the estimated camera parameters, in state order (the last ``m`` states)."""
        return tuple(self._native.estimated_parameters)

    @property
    def landmarks(self) -> npt.NDArray[np.void]:
        """``(N,)`` :data:`LANDMARK_DTYPE`: every landmark in state order (increasing id)."""
        ids, positions, covariances, observations = self._native.landmarks
        out = np.zeros(len(ids), dtype=LANDMARK_DTYPE)
        out["id"] = ids
        out["x"], out["y"], out["z"] = positions[:, 0], positions[:, 1], positions[:, 2]
        out["covariance"] = covariances
        out["observations"] = observations
        return out

    def landmark_covariance(self, id: int) -> _F64:
        """``(3, 3)`` float64: a landmark's position covariance. Raises :class:`InputError`
        for an id not in the map."""
        return self._native.landmark_covariance(_id("id", id))

    def landmark_state_index(self, id: int) -> int:
        """Index in :attr:`state` of a landmark's ``x`` (then ``y``, ``z``): its block of
        :attr:`covariance` is ``[i:i + 3, i:i + 3]``. Raises :class:`InputError` for an id
        not in the map. Indices shift when a landmark before it is removed."""
        return self._native.landmark_state_index(_id("id", id))

    def camera_state_index(self, name: str) -> int:
        """Index in :attr:`state` of an estimated camera parameter. Raises
        :class:`InputError` for a name not in :data:`CAMERA_PARAMETERS` or not estimated."""
        if not isinstance(name, str):
            raise InputTypeError(f"name must be a str, got {_describe(name)}")
        return self._native.camera_state_index(name)

    @property
    def health(self) -> Health:
        """Counters, the windowed NIS and the divergence flag."""
        return _health(self._native.health)

    @property
    def bindings(self) -> npt.NDArray[np.void]:
        """``(K,)`` :data:`BINDING_DTYPE`: every track bound to a landmark, by track."""
        return _bindings(self._native.bindings)

    @property
    def pending(self) -> int:
        """Tracks waiting for confirmation (:meth:`observe`)."""
        return self._native.pending

    @property
    def gate_bound(self) -> float:
        """The NIS bound of the innovation gate (4 dof) at ``gate_probability``."""
        return self._native.gate_bound

    @property
    def covariance_update(self) -> str:
        """The form of the covariance update, one of :data:`COVARIANCE_UPDATES`; settable at
        any time (both forms are exact, they differ in speed and in robustness to rounding)."""
        return self._native.covariance_update

    @covariance_update.setter
    def covariance_update(self, form: str) -> None:
        self._native.covariance_update = _form(form)


def _form(value: object) -> str:
    """A name of :data:`COVARIANCE_UPDATES`."""
    if not isinstance(value, str):
        raise InputTypeError(
            f"covariance_update must be a str (one of {COVARIANCE_UPDATES}), got {_describe(value)}"
        )
    if value not in COVARIANCE_UPDATES:
        raise InputError(f"covariance_update is {value!r}, expected one of {COVARIANCE_UPDATES}")
    return value


def _small_count(name: str, value: object) -> int:
    """A count of at least 1 that fits 32 bits."""
    number = _count(name, value, 1)
    if number > (1 << 32) - 1:
        raise InputError(f"{name} is {number}, expected an integer in 1..2**32")
    return number
