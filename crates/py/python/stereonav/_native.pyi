"""Stubs of the native module ``stereonav._native`` (``crates/py/src/lib.rs``).

Call the typed wrappers in :mod:`stereonav` instead; these functions check less.
"""

from typing import Any, Final, final

import numpy as np
import numpy.typing as npt

__all__ = [
    "__version__",
    "MAP_VERSION",
    "ODOMETRY_LOOKAHEAD_US",
    "read_map",
    "write_map",
    "import_map",
    "DEFAULT_LAMP_SIGMA_M",
    "LocalizeResult",
    "LocalizedFrames",
    "localize",
    "LogContents",
    "LogDamage",
    "LostSpan",
    "read_log",
    "BagContents",
    "BagFrame",
    "ImageCounts",
    "read_bag",
    "decode_image",
    "ImportedRig",
    "import_rig_kalibr",
    "import_rig_ros",
    "import_rig_opencv",
    "Navigator",
    "ReplayResult",
    "ReplayFrames",
    "FrameOutcome",
    "phase_names",
    "replay",
    "Filter",
    "MonteCarloResult",
    "FilterSettings",
    "Health",
    "monte_carlo",
    "CalibrationHistory",
    "CalibrationResult",
    "Handover",
    "LogCalibrationResult",
    "Observability",
    "PairSettings",
    "ParamObservability",
    "SolverSettings",
    "StableRule",
    "SelfCalibrator",
    "calibrate",
    "calibrate_log",
    "frame_pairs",
    "integrate_odometry",
    "FEATURE_RECORD_BYTES",
    "SimRun",
    "StreamDecoder",
    "Frame",
    "simulate",
    "camera_parameter_names",
    "vehicle_parameter_names",
    "Rig",
    "rectify_points",
    "rig_file_keys",
    "project",
    "triangulate",
    "encode_packet",
    "harris",
    "harris_response",
]

__version__: Final[str]
#: Bytes of one packed feature record: x_q4 u16, y_q4 u16, r i32, little-endian.
FEATURE_RECORD_BYTES: Final[int]

def harris(
    image: npt.NDArray[np.uint8], threshold: int, max_features: int
) -> tuple[npt.NDArray[np.uint8], bool]:
    """The board's Harris features of a 2-D uint8 image as packed 8-byte records.

    Returns ``(records, overflow)``: ``records`` is a 1-D uint8 array of ``8 * N`` bytes,
    one little-endian record ``x_q4`` u16, ``y_q4`` u16, ``r`` i32 per feature in raster
    order. Raises ``stereonav.InputError`` (a ``ValueError``) for values out of the board's
    ranges, ``TypeError`` for a non-uint8 or non-2-D array, and ``OverflowError`` for an
    integer beyond 64 bits (the wrapper :func:`stereonav.harris` checks all of these first).
    """

def harris_response(image: npt.NDArray[np.uint8]) -> npt.NDArray[np.int32]:
    """The board's Harris response map of a 2-D uint8 image: int32, shape (H, W), zero
    outside ``3 <= x <= W - 4``, ``3 <= y <= H - 4``. Raises ``stereonav.InputError`` (a
    ``ValueError``) for a size outside ``16..=4095``.
    """

@final
class Frame:
    """One good packet: a stereo frame's features as the board sent them."""

    @property
    def frame(self) -> int:
        """Frame counter (u32, +1 per stereo frame, wraps)."""
    @property
    def t_us(self) -> int:
        """Mid-exposure timestamp, microseconds, on the vehicle's clock."""
    @property
    def flags(self) -> int:
        """Bit 0: the left camera overflowed ``MAX_FEATURES``; bit 1: the right one did."""
    @property
    def lost_before(self) -> int:
        """Frames lost just before this one (gap in counters modulo 2**32)."""
    @property
    def left(self) -> npt.NDArray[np.void]:
        """The left camera's features, ``(N,)`` of ``FEATURE_DTYPE``, in the board's order."""
    @property
    def right(self) -> npt.NDArray[np.void]:
        """The right camera's features, ``(N,)`` of ``FEATURE_DTYPE``, in the board's order."""
    @property
    def left_overflow(self) -> bool:
        """Whether the left camera had more features than ``MAX_FEATURES``."""
    @property
    def right_overflow(self) -> bool:
        """Whether the right camera had more features than ``MAX_FEATURES``."""

@final
class StreamDecoder:
    """Push decoder of the board's byte stream."""

    def __init__(self) -> None: ...
    def push(self, data: bytes) -> list[Frame]:
        """Decode a chunk; return the frames it completed."""
    def finish(self) -> list[Frame]:
        """End the stream; return the frames found in a packet cut off by the end."""
    @property
    def stats(self) -> tuple[int, int, int, int]:
        """``(packets, corrupt, lost, bytes_skipped)``."""
    @property
    def buffered(self) -> int:
        """Bytes held waiting for the rest of a packet."""

def encode_packet(frame: int, t_us: int, flags: int, left: bytes, right: bytes) -> bytes:
    """One packet from packed left and right records; raises ``stereonav.InputError``."""

_F64 = npt.NDArray[np.float64]

def project(
    landmarks: _F64, pose_xyt: _F64, camera_params: _F64
) -> tuple[_F64, _F64, _F64, _F64]:
    """``(z (N,4), d_pose (N,4,3), d_landmark (N,4,3), d_camera (N,4,10))``."""

def triangulate(
    measurements: _F64, pose_xyt: _F64, camera_params: _F64, sigma_px: float
) -> tuple[_F64, _F64, _F64, _F64]:
    """``(p_in_rig, p_in_robot, p_in_world, cov_in_world)``."""

def rectify_points(points: _F64, rig: Rig, camera: str) -> _F64:
    """Raw pixels of one camera into the rectified rig model (NaN rows: not mappable)."""

def rig_file_keys() -> list[tuple[str, list[str]]]:
    """Every rig-file table and its keys, as the Rust reader reads them."""

@final
class Rig:
    """A rig file, checked: every table, held as the Rust rig (see ``stereonav.RigConfig``)."""

    @staticmethod
    def load(path: str) -> Rig:
        """Read a rig file (TOML); raises ``stereonav.InputError``."""
    @staticmethod
    def from_toml(text: str, source: str) -> Rig:
        """Parse a rig file's TOML text; raises ``stereonav.InputError``."""
    @staticmethod
    def from_json(text: str, source: str) -> Rig:
        """Parse the JSON form of a rig file; raises ``stereonav.InputError``."""
    @staticmethod
    def from_tables(tables: dict[str, Any], source: str) -> Rig:
        """A rig from its tables as a dict of dicts; raises ``stereonav.InputError``."""
    def tables(self) -> dict[str, Any]:
        """The rig file's tables as a dict of dicts."""
    def to_toml(self) -> str:
        """The rig file as TOML text."""
    def to_json(self) -> str:
        """The rig file's tables as JSON."""
    def __eq__(self, value: object, /) -> bool: ...
    @property
    def width(self) -> int:
        """Image width, pixels."""
    @property
    def height(self) -> int:
        """Image height, pixels."""
    @property
    def nominal(self) -> _F64:
        """The nominal camera, 10 values in ``CAMERA_PARAMETERS`` order."""
    @property
    def vehicle(self) -> _F64:
        """The nominal vehicle parameters, 4 values in ``VEHICLE_PARAMETERS`` order."""
    @property
    def estimate(self) -> list[str]:
        """Names of the estimated parameters."""
    @property
    def prior(self) -> dict[str, float]:
        """1-sigma prior of each estimated parameter, by name."""
    @property
    def pixel_noise(self) -> float:
        """Pixel noise (px, 1 sigma)."""
    @property
    def velocity_noise(self) -> float:
        """Odometry velocity noise per sample (m/s, 1 sigma)."""
    @property
    def yaw_rate_noise(self) -> float:
        """Odometry yaw-rate noise per sample (rad/s, 1 sigma)."""
    @property
    def velocity_tau(self) -> float:
        """Time constant of the odometry's velocity errors (s)."""
    @property
    def yaw_rate_tau(self) -> float:
        """Time constant of the odometry's yaw-rate errors (s)."""
    @property
    def board_threshold(self) -> int:
        """The board's THRESHOLD register."""
    @property
    def board_max_features(self) -> int:
        """The board's MAX_FEATURES register."""
    @property
    def has_lens(self) -> bool:
        """Whether the rig has lens tables."""

def camera_parameter_names() -> list[str]:
    """The ten camera parameter names in array order."""

def vehicle_parameter_names() -> list[str]:
    """The four vehicle parameter names (``V``) in ``SUMMARY.json``'s order."""

@final
class SimRun:
    """One simulated run (see ``stereonav.Simulation``)."""

    @property
    def name(self) -> str: ...
    @property
    def seed(self) -> int: ...
    @property
    def mode(self) -> str: ...
    @property
    def camera(self) -> _F64: ...
    @property
    def rig_toml(self) -> str: ...
    @property
    def frame_t_us(self) -> npt.NDArray[np.uint64]: ...
    @property
    def frame_poses(self) -> _F64: ...
    @property
    def visible(self) -> npt.NDArray[np.uint64]: ...
    @property
    def landmarks(self) -> _F64: ...
    @property
    def odometry(self) -> _F64: ...
    @property
    def odometry_truth(self) -> _F64: ...
    @property
    def stream(self) -> bytes: ...
    def truth_json(self) -> str:
        """Ground truth as JSON."""
    def write_log(self, path: str) -> None:
        """Write the vehicle log (MCAP)."""

def simulate(scenario: str, rendered: bool, seed: int | None = None) -> SimRun:
    """Simulate a scenario file; raises ``stereonav.InputError``."""

_U64 = npt.NDArray[np.uint64]
#: ``(pair (N,), uL0 vL0 uR0 vR0 uL1 vL1 uR1 vR1 (N, 8))``.
_Observations = tuple[_U64, _F64]
#: ``(t_us (P,), dx dy dtheta dt_s (P, 4), samples (P,))``.
_Motions = tuple[_U64, _F64, _U64]
#: ``(t_us (S,), vx vy vtheta (S, 3))``.
_Odometry = tuple[_U64, _F64]

@final
class SolverSettings:
    """The phase-1 solver's settings; a keyword left out takes the Rust default."""

    def __new__(
        cls,
        *,
        huber: float | None = None,
        max_iterations: int | None = None,
        step_tolerance: float | None = None,
        observable_ratio: float | None = None,
    ) -> SolverSettings: ...
    @property
    def huber(self) -> float:
        """Huber threshold on a landmark's Mahalanobis norm."""
    @property
    def max_iterations(self) -> int:
        """Most Levenberg-Marquardt iterations."""
    @property
    def step_tolerance(self) -> float:
        """Converged when every step is below this fraction of the parameter's sigma."""
    @property
    def observable_ratio(self) -> float:
        """Observable when the data bring a sigma to at most this fraction of its prior."""

@final
class StableRule:
    """The incremental calibration's stability rule and solve interval; a keyword left out
    takes the Rust default."""

    def __new__(
        cls,
        *,
        min_pairs: int | None = None,
        sigma_fraction: float | None = None,
        step_fraction: float | None = None,
        consecutive: int | None = None,
        solve_every: int | None = None,
    ) -> StableRule: ...
    @property
    def min_pairs(self) -> int:
        """Pairs at least, before calibration can be stable."""
    @property
    def sigma_fraction(self) -> float:
        """Each observable sigma at most this fraction of its prior sigma."""
    @property
    def step_fraction(self) -> float:
        """Each step between two solves below this fraction of the sigma."""
    @property
    def consecutive(self) -> int:
        """Solves in a row that must meet the rule."""
    @property
    def solve_every(self) -> int:
        """Pairs between two solves."""

@final
class PairSettings:
    """How a log's frames become frame pairs; a keyword left out takes the Rust default."""

    def __new__(cls, *, stride: int | None = None, pairing: str | None = None) -> PairSettings: ...
    @property
    def stride(self) -> int:
        """Frames from the first frame of a pair to its second."""
    @property
    def pairing(self) -> str:
        """``"disjoint"`` or ``"interleaved"``."""

@final
class ParamObservability:
    """How well the data constrain one estimated parameter (compared by value)."""

    def __eq__(self, value: object, /) -> bool: ...
    def __ne__(self, value: object, /) -> bool: ...
    def __hash__(self) -> int: ...
    @property
    def name(self) -> str:
        """The parameter (one of ``CAMERA_PARAMETERS``)."""
    @property
    def prior_sigma(self) -> float:
        """Its prior sigma (rig file ``[prior]``)."""
    @property
    def data_sigma(self) -> float:
        """Its sigma from the data alone (``inf`` when the data say nothing about it)."""
    @property
    def posterior_sigma(self) -> float:
        """Its sigma from data and prior together."""
    @property
    def observable(self) -> bool:
        """Whether the data constrain it."""
    @property
    def reason(self) -> str | None:
        """Why it is not observable, or None."""
    @property
    def structural(self) -> bool:
        """Not observable because of a known trap of the rig and the path."""

@final
class Observability:
    """The observability analysis of the estimated parameters."""

    @property
    def params(self) -> list[ParamObservability]:
        """One record per estimated parameter, in ``CAMERA_PARAMETERS`` order."""
    @property
    def max_correlation(self) -> tuple[str, str, float] | None:
        """``(a, b, r)``: the most correlated pair of observable parameters, or None."""
    @property
    def eigenvalues(self) -> _F64:
        """The information eigenvalues in prior-sigma units, ascending, ``(E,)``."""

@final
class Handover:
    """What phase 1 hands to phase 2 once calibration is stable."""

    @property
    def camera(self) -> _F64:
        """The calibrated camera, ``(10,)``."""
    @property
    def covariance(self) -> _F64:
        """Its covariance, ``(10, 10)``."""
    @property
    def t_us(self) -> int:
        """Time of the frame at which calibration became stable."""
    @property
    def observability(self) -> Observability:
        """The observability analysis at hand-over."""

@final
class CalibrationHistory:
    """The camera parameters after each solve of an incremental calibration (K solves)."""

    @property
    def t_us(self) -> _U64:
        """``(K,)``: time of the last frame pair of each solve."""
    @property
    def values(self) -> _F64:
        """``(K, 10)``: the parameters."""
    @property
    def sigmas(self) -> _F64:
        """``(K, 10)``: their sigmas."""

@final
class CalibrationResult:
    """The result of a phase-1 solve (see ``stereonav.Calibration``)."""

    @property
    def camera(self) -> _F64: ...
    @property
    def covariance(self) -> _F64: ...
    @property
    def status(self) -> str: ...
    @property
    def iterations(self) -> int: ...
    @property
    def residuals(self) -> int: ...
    @property
    def outliers(self) -> int: ...
    @property
    def reduced_chi2(self) -> float: ...
    @property
    def observability(self) -> Observability: ...
    @property
    def history(self) -> _F64: ...

def calibrate(
    rig: Rig,
    observations: _Observations,
    motions: _Motions,
    start: _F64 | None,
    settings: SolverSettings,
) -> CalibrationResult:
    """Phase-1 batch solve of frame pairs as tables; raises ``stereonav.InputError``."""

def integrate_odometry(odometry: _Odometry, t0_us: _U64, t1_us: _U64) -> tuple[_F64, _U64]:
    """``(dx dy dtheta dt_s (P, 4), samples (P,))`` of each span; raises ``stereonav.InputError``."""

def frame_pairs(
    measurements: tuple[_U64, _U64, _F64], odometry: _Odometry, stride: int
) -> tuple[_Observations, _Motions]:
    """Frame pairs by landmark id from ``(t_us, id, uL vL uR vR (N, 4))``; raises
    ``stereonav.InputError``."""

@final
class SelfCalibrator:
    """Phase 1 fed pair by pair (see ``stereonav.SelfCalibrator``)."""

    def __new__(cls, rig: Rig, settings: SolverSettings, rule: StableRule) -> SelfCalibrator: ...
    def add_pairs(self, observations: _Observations, motions: _Motions) -> int:
        """Add frame pairs; return the number of solves they triggered."""
    @property
    def latest(self) -> CalibrationResult | None: ...
    @property
    def handover(self) -> Handover | None: ...
    @property
    def history(self) -> CalibrationHistory: ...
    @property
    def pairs(self) -> int: ...

@final
class LogCalibrationResult:
    """Phase 1 on a whole vehicle log (see ``stereonav.LogCalibration``)."""

    def document_json(self) -> str:
        """The ``stereonav calibrate --out`` document as JSON text."""
    @property
    def calibration(self) -> CalibrationResult: ...
    @property
    def handover(self) -> Handover | None: ...
    @property
    def history(self) -> CalibrationHistory: ...
    @property
    def counts(self) -> list[tuple[str, int]]: ...
    @property
    def warnings(self) -> list[str]: ...
    @property
    def rig_source(self) -> str: ...

def calibrate_log(
    log_path: str,
    rig: Rig | None,
    pairs: PairSettings,
    settings: SolverSettings,
    rule: StableRule,
) -> LogCalibrationResult:
    """Phase 1 on a vehicle log (read, decode, associate, solve); raises
    ``stereonav.InputError`` naming the file or the setting."""

#: ``(accepted ids (A,), accepted NIS (A,), rejected ids (R,), rejected NIS (R,), removed (D,))``.
_UpdateTuple = tuple[_U64, _F64, _U64, _F64, _U64]
#: ``(update, added (K, 2), removed (K, 2), ignored, pending)``; pairs are ``(track, landmark)``.
_FrameTuple = tuple[_UpdateTuple, _U64, _U64, int, int]

@final
class FilterSettings:
    """The settings of :class:`Filter`; a keyword left out takes the Rust default."""

    def __new__(
        cls,
        *,
        gate_probability: float | None = None,
        nis_window: int | None = None,
        max_consecutive_rejections: int | None = None,
        covariance_update: str | None = None,
        frames_to_confirm: int | None = None,
        consistency_probability: float | None = None,
    ) -> FilterSettings: ...
    @property
    def gate_probability(self) -> float:
        """Probability mass inside each observation's innovation gate (4 dof)."""
    @property
    def nis_window(self) -> int:
        """Gate outcomes kept for the health's NIS statistics."""
    @property
    def max_consecutive_rejections(self) -> int:
        """A landmark rejected this many times in a row is removed as false."""
    @property
    def covariance_update(self) -> str:
        """``"auto"``, ``"joseph"`` or ``"factored"``."""
    @property
    def frames_to_confirm(self) -> int:
        """Consecutive consistent frames before a track becomes a landmark."""
    @property
    def consistency_probability(self) -> float:
        """Probability mass inside a candidate's consistency gate (3 dof)."""

@final
class Health:
    """The filter's health: counters, the NIS over a sliding window, a divergence flag."""

    @property
    def updates(self) -> int:
        """Updates applied."""
    @property
    def refused_updates(self) -> int:
        """Updates refused."""
    @property
    def accepted(self) -> int:
        """Observations accepted by the gate, in all."""
    @property
    def rejected(self) -> int:
        """Observations rejected by the gate, in all."""
    @property
    def landmarks_added(self) -> int:
        """Landmarks added, in all."""
    @property
    def landmarks_removed(self) -> int:
        """Landmarks removed, in all."""
    @property
    def window_observations(self) -> int:
        """Gate outcomes in the window."""
    @property
    def window_rejected(self) -> int:
        """Rejections among them."""
    @property
    def window_mean_nis_per_dof(self) -> float | None:
        """Mean NIS per dof of the accepted observations in the window, or None."""
    @property
    def window_nis_bound(self) -> float | None:
        """That mean's 99.9 % bound, or None."""
    @property
    def nis_too_high(self) -> bool:
        """The window mean is above its bound."""
    @property
    def diverged(self) -> bool:
        """``nis_too_high``, or an update was ever refused."""


@final
class Filter:
    """Phase 2, the EKF with the camera in the state (see ``stereonav.Filter``)."""

    def __new__(
        cls, rig: Rig, start: tuple[_F64, _F64] | None, settings: FilterSettings
    ) -> Filter: ...
    def copy(self) -> Filter:
        """An independent copy."""
    def predict(self, vx: float, vy: float, vtheta: float, dt_s: float) -> None:
        """Eq. 3-4 with velocities held for ``dt_s``."""
    def predict_odometry(self, odometry: _Odometry, t0_us: int, t1_us: int) -> None:
        """Eq. 3-4 over ``[t0_us, t1_us]``."""
    def update(self, ids: _U64, z: _F64) -> _UpdateTuple:
        """Eq. 5-8 by landmark id."""
    def observe(self, tracks: _U64, z: _F64) -> _FrameTuple:
        """One frame keyed by track id."""
    def add_landmark(self, z: _F64) -> int:
        """A new landmark from one measurement; its id."""
    def remove_landmark(self, id: int) -> None:
        """Removes a landmark."""
    def predict_measurement(self, id: int) -> tuple[_F64, _F64]:
        """``(z (4,), S (4, 4))``."""
    def measurement_jacobian(self, id: int) -> tuple[_F64, _F64]:
        """``(z (4,), H (4, n))``."""
    def prediction_jacobian(self, id: int) -> tuple[_F64, _F64]:
        """``(z (4,), H (4, n))``: the Jacobian ``predict_measurement``'s ``S`` is formed with."""
    @property
    def state(self) -> _F64: ...
    @property
    def covariance(self) -> _F64: ...
    @property
    def pose(self) -> _F64: ...
    @property
    def pose_covariance(self) -> _F64: ...
    @property
    def camera(self) -> _F64: ...
    @property
    def camera_covariance(self) -> _F64: ...
    @property
    def estimated_parameters(self) -> list[str]: ...
    @property
    def landmarks(self) -> tuple[_U64, _F64, _F64, _U64]:
        """``(ids (N,), positions (N, 3), covariances (N, 3, 3), observations (N,))``."""
    def landmark_covariance(self, id: int) -> _F64:
        """``(3, 3)``."""
    def landmark_state_index(self, id: int) -> int:
        """Index of the landmark's ``x`` in the state."""
    def camera_state_index(self, name: str) -> int:
        """Index of an estimated camera parameter in the state."""
    @property
    def health(self) -> Health: ...
    @property
    def bindings(self) -> _U64:
        """``(K, 2)``: ``(track, landmark)``."""
    @property
    def pending(self) -> int: ...
    @property
    def gate_bound(self) -> float: ...
    @property
    def covariance_update(self) -> str: ...
    @covariance_update.setter
    def covariance_update(self, form: str) -> None: ...

_Banded = tuple[float, float, float]

@final
class MonteCarloResult:
    """Phase-2 Monte Carlo runs (see ``stereonav.MonteCarloSummary``)."""

    @property
    def seeds(self) -> _U64: ...
    @property
    def frames(self) -> _U64: ...
    @property
    def landmark_rms(self) -> _F64: ...
    @property
    def landmarks(self) -> _U64: ...
    @property
    def lamps_missing(self) -> _U64: ...
    @property
    def camera_parameters(self) -> list[str]: ...
    @property
    def camera_value(self) -> _F64: ...
    @property
    def camera_truth(self) -> _F64: ...
    @property
    def camera_sigma(self) -> _F64: ...
    @property
    def within_3_sigma(self) -> npt.NDArray[np.bool_]: ...
    @property
    def healthy(self) -> npt.NDArray[np.bool_]: ...
    @property
    def pose_nees(self) -> _F64: ...
    @property
    def state_nees(self) -> _F64: ...
    @property
    def state_nees_dof(self) -> _U64: ...
    @property
    def mean_nis(self) -> _F64: ...
    @property
    def accepted(self) -> _U64: ...
    @property
    def rejected(self) -> _U64: ...
    @property
    def outliers(self) -> _U64: ...
    @property
    def outliers_accepted(self) -> _U64: ...
    @property
    def refused_updates(self) -> _U64: ...
    @property
    def pose_error(self) -> _F64: ...
    @property
    def pose_nees_band(self) -> _Banded: ...
    @property
    def pose_nees_frames_inside(self) -> float: ...
    @property
    def state_nees_per_dof_band(self) -> _Banded: ...
    @property
    def state_nees_frames_inside(self) -> float: ...
    @property
    def nis_band(self) -> _Banded: ...
    @property
    def within_3_sigma_count(self) -> int: ...
    @property
    def healthy_count(self) -> int: ...

def monte_carlo(
    scenario: str, runs: int, first_seed: int, outlier_fraction: float, max_frames: int | None
) -> MonteCarloResult:
    """Phase-2 Monte Carlo on a scenario file; raises ``stereonav.InputError``."""

#: ``(ids (N,), positions (N, 3), covariances (N, 3, 3), observations (N,))``.
_LandmarkTuple = tuple[_U64, _F64, _F64, _U64]
#: ``(values (10,), sigmas (10,))`` in ``CAMERA_PARAMETERS`` order.
_CameraTuple = tuple[_F64, _F64]

@final
class ReplayFrames:
    """Every frame of a replay, as columns (F frames)."""

    @property
    def t_us(self) -> _U64:
        """``(F,)``: the frame's time."""
    @property
    def phase(self) -> npt.NDArray[np.uint8]:
        """``(F,)``: the phase, an index into :func:`phase_names`."""
    @property
    def pose(self) -> _F64:
        """``(F, 3)``: the pose ``X, Y, theta`` after the frame."""
    @property
    def pose_covariance(self) -> _F64:
        """``(F, 3, 3)``: its covariance."""
    @property
    def accepted(self) -> _U64:
        """``(F,)``: observations the gate let through."""
    @property
    def rejected(self) -> _U64:
        """``(F,)``: observations the gate left out."""
    @property
    def landmarks(self) -> _U64:
        """``(F,)``: landmarks in the map after the frame."""

@final
class FrameOutcome:
    """What one frame of :class:`Navigator` did."""

    @property
    def accepted(self) -> _U64:
        """``(A,)``: landmarks updated at this frame."""
    @property
    def accepted_nis(self) -> _F64:
        """``(A,)``: their NIS (4 dof)."""
    @property
    def rejected(self) -> _U64:
        """``(R,)``: landmarks whose observation the gate left out."""
    @property
    def added(self) -> _U64:
        """``(K,)``: landmarks added."""
    @property
    def removed(self) -> _U64:
        """``(D,)``: landmarks removed as false."""
    @property
    def rematched(self) -> _U64:
        """``(M, 2)``: ``(track, landmark)`` pairs bound by map matching."""
    @property
    def solved(self) -> bool:
        """Phase 1 solved at this frame."""
    @property
    def switched(self) -> bool:
        """The switch to phase 2 happened at this frame."""
    @property
    def no_odometry(self) -> bool:
        """The odometry did not reach back to the previous frame: the pose was held."""

def phase_names() -> list[str]:
    """The phase names, in the order of the per-frame phase codes."""

@final
class ReplayResult:
    """A whole log replayed (see ``stereonav.Replay``)."""

    def summary_json(self) -> str:
        """``SUMMARY.json`` as JSON text."""
    @property
    def frames(self) -> ReplayFrames: ...
    @property
    def nis(self) -> tuple[_U64, _U64, _F64]:
        """``(t_us (K,), landmark id (K,), NIS (K,))``."""
    @property
    def camera_history(self) -> tuple[_U64, npt.NDArray[np.uint8], _F64, _F64]:
        """``(t_us (K,), phase (K,), values (K, 10), sigmas (K, 10))``."""
    @property
    def camera(self) -> _CameraTuple: ...
    @property
    def vehicle(self) -> _CameraTuple: ...
    @property
    def landmarks(self) -> _LandmarkTuple: ...
    @property
    def maps(self) -> list[tuple[int, _LandmarkTuple]]: ...
    @property
    def phase_switch_t_us(self) -> int | None: ...
    @property
    def phase1_skipped(self) -> bool: ...
    @property
    def counts(self) -> list[tuple[str, int]]: ...
    @property
    def warnings(self) -> list[str]: ...
    def write_estimates(self, path: str) -> None:
        """Write ``EST.mcap``; raises ``stereonav.InputError``."""
    def write_summary(self, path: str) -> None:
        """Write ``SUMMARY.json``; raises ``stereonav.InputError``."""
    def write_trajectory(self, path: str) -> None:
        """Write ``TRAJ.csv``; raises ``stereonav.InputError``."""
    def write_trajectory_tum(self, path: str) -> None:
        """Write the trajectory as TUM; raises ``stereonav.InputError``."""

def replay(
    log_path: str,
    rig: Rig | None,
    skip_phase1: bool,
    phase1_frames: int | None,
    consider_camera: bool,
    save_map: str | None,
    left: str | None = None,
    right: str | None = None,
    odom: str | None = None,
) -> ReplayResult:
    """The whole stack on a vehicle log, the map it built written to ``save_map`` (unless
    None); raises ``stereonav.InputError`` naming the file or the setting."""

#: The newest map format version read (docs/maps.md); a map is written as 1, or 2 without a rig.
MAP_VERSION: Final[int]
#: The 1-sigma position of a lamp whose row of a lighting plan gives none, metres.
DEFAULT_LAMP_SIGMA_M: Final[float]
ODOMETRY_LOOKAHEAD_US: Final[int]

def read_map(path: str) -> str:
    """The JSON body of a map file after every check of ``map_file::Map::load``; raises
    ``stereonav.InputError`` naming the file and the problem (the ``OSError`` as
    ``__cause__`` when the OS refused the file)."""

def write_map(body: str, path: str) -> None:
    """Write the map whose JSON body is ``body``, checked as a file's body (and for the
    version and unknown keys); raises ``stereonav.InputError`` naming the key or the file."""

def import_map(csv_path: str, out_path: str | None, sigma: float, rig: Rig | None) -> str:
    """The map of the lighting plan at ``csv_path`` (``stereonav map import``), written to
    ``out_path`` unless None, as its JSON body; raises ``stereonav.InputError`` naming the
    file, the line and the problem."""

@final
class LocalizedFrames:
    """Every frame of a localisation run, as columns (F frames)."""

    @property
    def t_us(self) -> _U64:
        """``(F,)``: the frame's time."""
    @property
    def pose(self) -> _F64:
        """``(F, 3)``: the pose ``X, Y, theta`` in the map's frame, NaN without a guess."""
    @property
    def sigma(self) -> _F64:
        """``(F, 3)``: its 1-sigma, NaN without a pose."""
    @property
    def localized(self) -> npt.NDArray[np.bool_]:
        """``(F,)``: the localiser stands behind the pose."""
    @property
    def matched(self) -> npt.NDArray[np.uint32]:
        """``(F,)``: map lamps associated at the frame."""
    @property
    def hypotheses(self) -> npt.NDArray[np.uint32]:
        """``(F,)``: live relocalisation hypotheses."""

@final
class LocalizeResult:
    """A vehicle log run on a saved map (see ``stereonav.Localization``)."""

    def summary_json(self) -> str:
        """``SUMMARY.json`` of ``stereonav localize`` as JSON text."""
    @property
    def frames(self) -> LocalizedFrames: ...
    @property
    def localized_t_us(self) -> list[int]: ...
    @property
    def lamps_missing(self) -> list[int]: ...
    @property
    def new_lamps(self) -> tuple[_F64, _F64, _U64]:
        """``(positions (K, 3), covariances (K, 3, 3), observations (K,))``."""
    @property
    def counts(self) -> list[tuple[str, int]]: ...
    @property
    def warnings(self) -> list[str]: ...
    def write_summary(self, path: str) -> None:
        """Write ``SUMMARY.json``; raises ``stereonav.InputError``."""
    def write_trajectory(self, path: str) -> None:
        """Write ``TRAJ.csv``; raises ``stereonav.InputError``."""
    def write_trajectory_tum(self, path: str) -> None:
        """Write the trajectory as TUM; raises ``stereonav.InputError``."""

def localize(
    log_path: str,
    map_path: str,
    rig: Rig | None,
    save_map: str | None,
    left: str | None = None,
    right: str | None = None,
    odom: str | None = None,
) -> LocalizeResult:
    """A vehicle log on the saved map at ``map_path``, the map with the run's new lamps
    written to ``save_map`` (unless None); raises ``stereonav.InputError`` naming the file
    and the problem."""

@final
class Navigator:
    """Both phases of the method fed frame by frame (see ``stereonav.Navigator``)."""

    def __new__(
        cls,
        rig: Rig,
        skip_phase1: bool,
        phase1_frames: int | None,
        consider_camera: bool,
    ) -> Navigator: ...
    def push_odometry(self, t_us: _U64, values: _F64) -> None:
        """Odometry ``(t_us (S,), vx vy vtheta (S, 3))``, sorted, none older than before."""
    def push_frame(self, t_us: int, left: _F64, right: _F64) -> FrameOutcome:
        """One stereo frame, features ``(N, 2)`` pixels ``u, v`` a side."""
    def finish(self) -> bool:
        """The end of the drive: phase 1 hands over if still running; phase 2's smoother solves."""
    @property
    def phase(self) -> str: ...
    @property
    def phase_switch_t_us(self) -> int | None: ...
    @property
    def last_frame_t_us(self) -> int | None: ...
    @property
    def pose(self) -> _F64: ...
    @property
    def pose_covariance(self) -> _F64: ...
    @property
    def camera(self) -> _CameraTuple: ...
    @property
    def vehicle(self) -> _CameraTuple: ...
    @property
    def camera_covariance(self) -> _F64: ...
    @property
    def landmarks(self) -> _LandmarkTuple: ...
    @property
    def stats(self) -> list[tuple[str, int]]: ...

@final
class LogContents:
    """A vehicle log read whole, as logged (see ``stereonav.VehicleLog``)."""

    @property
    def stream(self) -> bytes:
        """Every ``/fpga/features`` chunk concatenated in log order."""
    @property
    def chunks(self) -> int:
        """Number of ``/fpga/features`` messages."""
    @property
    def odometry(self) -> tuple[_U64, _F64]:
        """``(t_us (S,), vx vy vtheta (S, 3))`` in log order."""
    @property
    def rig_json(self) -> str | None:
        """The first ``/rig`` message's text, or None."""
    def rig(self) -> Rig | None:
        """The first ``/rig`` message as a rig, or None; raises
        ``stereonav.InputError`` for an invalid rig."""
    @property
    def truth_poses(self) -> tuple[_U64, _F64]:
        """``(t_us (F,), x y theta (F, 3))`` in log order; empty without truth."""
    @property
    def truth_landmarks(self) -> tuple[_U64, _F64]:
        """``(id (N,), x y z (N, 3))``; empty without truth."""
    @property
    def truth_camera(self) -> _F64 | None:
        """10 values in ``CAMERA_PARAMETERS`` order, or None."""
    @property
    def warnings(self) -> list[str]: ...
    @property
    def truncated(self) -> str | None: ...
    @property
    def damage(self) -> LogDamage:
        """What could not be read."""
    @property
    def ignored_messages(self) -> int: ...
    @property
    def ignored_topics(self) -> list[str]: ...
    @property
    def topics(self) -> list[str]: ...

@final
class LostSpan:
    """One stretch of a log that could not be read, in file order."""

    @property
    def offset(self) -> int:
        """File offset of the first byte not used."""
    @property
    def bytes(self) -> int:
        """Bytes of the file not used."""
    @property
    def start_ns(self) -> int | None:
        """Log time (ns) of the first message lost, or of the last good one before."""
    @property
    def end_ns(self) -> int | None:
        """Log time (ns) of the last message lost, or of the first good one after."""
    @property
    def exact_times(self) -> bool:
        """Whether ``start_ns..end_ns`` is the lost messages' own span (else the bounds)."""
    @property
    def chunks(self) -> int:
        """Chunk records lost, wholly or in part."""
    @property
    def messages(self) -> dict[str, int] | None:
        """Messages lost per topic, or None when nothing tells."""
    @property
    def why(self) -> str:
        """What was wrong, one line."""

@final
class LogDamage:
    """What could not be read in a log, in total."""

    @property
    def damaged(self) -> bool:
        """Whether anything is damaged."""
    @property
    def spans(self) -> list[LostSpan]:
        """The first 256 spans lost, in file order."""
    @property
    def spans_total(self) -> int: ...
    @property
    def bytes_lost(self) -> int: ...
    @property
    def chunks_lost(self) -> int: ...
    @property
    def messages_lost(self) -> dict[str, int] | None:
        """Messages lost per topic, or None when nothing counts them."""
    @property
    def header_damaged(self) -> bool: ...
    @property
    def tail_damaged(self) -> bool: ...
    @property
    def cut(self) -> bool: ...
    @property
    def summary(self) -> str:
        """``"intact"``, ``"damaged"`` or ``"absent"``."""
    @property
    def summary_problem(self) -> str | None: ...
    @property
    def unverified_chunks(self) -> int: ...
    @property
    def repaired_chunks(self) -> int: ...

def read_log(path: str) -> LogContents:
    """Read a vehicle log whole with the GIL released; raises ``stereonav.InputError`` (the
    ``OSError`` as ``__cause__`` when the OS refused the file, the replay's message for a file
    without the vehicle topics)."""

@final
class ImageCounts:
    """What became of a bag's camera images (``host_board::ImageCounts``)."""

    @property
    def left(self) -> int:
        """Left images read."""
    @property
    def right(self) -> int:
        """Right images read."""
    @property
    def frames(self) -> int:
        """Stereo frames detected (both images read)."""
    @property
    def unpaired(self) -> int:
        """Images without a partner within a quarter of the frame interval."""
    @property
    def wrong_size(self) -> int:
        """Images of another size than the rig's ``[camera]``."""
    @property
    def unsupported(self) -> int:
        """Images of an encoding or format that is not read."""
    @property
    def undecodable(self) -> int:
        """Images whose bytes or message do not decode."""
    @property
    def frames_dropped(self) -> int:
        """Frames lost because one of their images could not be read."""
    @property
    def problems(self) -> list[str]:
        """The first problem of each kind, one line each."""
    def __eq__(self, value: object, /) -> bool: ...
    def __ne__(self, value: object, /) -> bool: ...
    __hash__: None  # type: ignore[assignment]

@final
class BagFrame:
    """One stereo frame of a bag, detected on the host."""

    @property
    def t_us(self) -> int:
        """The left image's stamp, microseconds."""
    @property
    def left(self) -> npt.NDArray[np.void]:
        """The left image's features, ``(N,)`` of ``FEATURE_DTYPE``, in the board's order."""
    @property
    def right(self) -> npt.NDArray[np.void]:
        """The right image's features."""
    @property
    def overflow(self) -> bool:
        """Either image had more than ``MAX_FEATURES`` features."""

@final
class BagContents:
    """A ROS 2 bag read whole with the board on the host (see ``stereonav.Ros2Bag``)."""

    @property
    def frames(self) -> list[BagFrame]:
        """The stereo frames in stamp order."""
    @property
    def images(self) -> ImageCounts | None:
        """The image counts; None without camera topics."""
    @property
    def odometry(self) -> tuple[_U64, _F64]:
        """``(t_us (S,), vx vy vtheta (S, 3))`` in log order."""
    @property
    def topics(self) -> list[tuple[str, str, str]]:
        """``(argument, topic, type)`` of each named topic."""
    @property
    def messages(self) -> list[int]:
        """Messages read on the left, right and odometry topics."""
    @property
    def warnings(self) -> list[str]: ...
    @property
    def truncated(self) -> str | None: ...
    @property
    def damage(self) -> LogDamage: ...

def read_bag(
    log_path: str,
    rig: Rig | None,
    left: str | None,
    right: str | None,
    odom: str | None,
) -> BagContents:
    """Read a ROS 2 bag whole with the board on the host; raises ``stereonav.InputError``."""

def decode_image(data: bytes) -> npt.NDArray[np.uint8]:
    """A PNG or JPEG file's bytes to gray ``(H, W)`` as the host decodes them; raises
    ``stereonav.InputError``."""

@final
class ImportedRig:
    """A calibration imported as a rig file (see ``stereonav.import_rig``)."""

    @property
    def rig(self) -> Rig:
        """The rig, exactly as ``toml`` reads back."""
    @property
    def toml(self) -> str:
        """The commented rig file, byte for byte what ``stereonav rig import --out`` writes."""
    @property
    def provenance(self) -> str:
        """Where the calibration came from and how it was rectified."""
    @property
    def summary(self) -> str:
        """The line ``stereonav rig import`` prints after the file's name."""
    @property
    def baseline_warning(self) -> str | None:
        """The command line's warning for a baseline over 2 (metres expected), else None."""

def import_rig_kalibr(path: str) -> ImportedRig:
    """Kalibr's ``camchain.yaml`` as a rig; raises ``stereonav.InputError``."""

def import_rig_ros(left: str, right: str) -> ImportedRig:
    """The ROS ``camera_info`` files of the left and the right camera as a rig; raises
    ``stereonav.InputError``."""

def import_rig_opencv(path: str) -> ImportedRig:
    """OpenCV's ``FileStorage`` stereo calibration as a rig; raises ``stereonav.InputError``."""
