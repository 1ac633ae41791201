"""Stubs of the native module ``stereonav._native`` (``crates/py/src/lib.rs``).

Call the typed wrappers in :mod:`stereonav` instead; these functions check less.
"""

from typing import Final, final

import numpy as np
import numpy.typing as npt

__all__ = [
    "__version__",
    "LogContents",
    "LogDamage",
    "LostSpan",
    "read_log",
    "Navigator",
    "ReplayResult",
    "phase_names",
    "replay",
    "Filter",
    "MonteCarloResult",
    "filter_defaults",
    "monte_carlo",
    "CalibrationResult",
    "LogCalibrationResult",
    "SelfCalibrator",
    "calibrate",
    "calibrate_log",
    "frame_pairs",
    "integrate_odometry",
    "solver_defaults",
    "stable_rule_defaults",
    "FEATURE_RECORD_BYTES",
    "SimRun",
    "StreamDecoder",
    "simulate",
    "camera_parameter_names",
    "load_rig",
    "rectify_points",
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

_RawFrame = tuple[int, int, int, int, npt.NDArray[np.uint8], npt.NDArray[np.uint8]]

@final
class StreamDecoder:
    """Push decoder of the board's byte stream; frames as raw tuples
    ``(frame, t_us, flags, lost_before, left_records, right_records)``."""

    def __init__(self) -> None: ...
    def push(self, data: bytes) -> list[_RawFrame]:
        """Decode a chunk; return the frames it completed."""
    def finish(self) -> list[_RawFrame]:
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

def rectify_points(points: _F64, path: str, camera: str) -> _F64:
    """Raw pixels of one camera into the rectified rig model (NaN rows: not mappable)."""

def load_rig(
    path: str,
) -> tuple[int, int, list[float], list[str], list[tuple[str, float]], tuple[float, float, float]]:
    """The rig file's values; raises ``stereonav.InputError``."""

def camera_parameter_names() -> list[str]:
    """The ten camera parameter names in array order."""

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
#: ``(huber, max_iterations, step_tolerance, observable_ratio)``.
_Settings = tuple[float, int, float, float]
#: ``(min_pairs, sigma_fraction, step_fraction, consecutive)``.
_Rule = tuple[int, float, float, int]
#: ``(name, prior_sigma, data_sigma, posterior_sigma, observable, reason, structural)``.
_ParamRecord = tuple[str, float, float, float, bool, "str | None", bool]
#: ``(params, max_correlation (a, b, r) or None, eigenvalues)``.
_Observability = tuple[list[_ParamRecord], "tuple[str, str, float] | None", _F64]
#: ``(camera (10,), covariance (10, 10), t_us, observability)``.
_Handover = tuple[_F64, _F64, int, _Observability]
#: ``(t_us (K,), values (K, 10), sigmas (K, 10))``.
_History = tuple[_U64, _F64, _F64]

def solver_defaults() -> _Settings:
    """The default solver settings ``(huber, max_iterations, step_tolerance, observable_ratio)``."""

def stable_rule_defaults() -> _Rule:
    """The default stability rule ``(min_pairs, sigma_fraction, step_fraction, consecutive)``."""

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
    def observability(self) -> _Observability: ...
    @property
    def history(self) -> _F64: ...

def calibrate(
    rig_json: str,
    rig_source: str,
    observations: _Observations,
    motions: _Motions,
    start: _F64 | None,
    settings: _Settings,
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

    def __new__(
        cls, rig_json: str, rig_source: str, settings: _Settings, rule: _Rule, solve_every: int
    ) -> SelfCalibrator: ...
    def add_pairs(self, observations: _Observations, motions: _Motions) -> int:
        """Add frame pairs; return the number of solves they triggered."""
    @property
    def latest(self) -> CalibrationResult | None: ...
    @property
    def handover(self) -> _Handover | None: ...
    @property
    def history(self) -> _History: ...
    @property
    def pairs(self) -> int: ...

@final
class LogCalibrationResult:
    """Phase 1 on a whole vehicle log (see ``stereonav.LogCalibration``)."""

    @property
    def calibration(self) -> CalibrationResult: ...
    @property
    def handover(self) -> _Handover | None: ...
    @property
    def history(self) -> _History: ...
    @property
    def counts(self) -> list[tuple[str, int]]: ...
    @property
    def warnings(self) -> list[str]: ...
    @property
    def rig_source(self) -> str: ...

def calibrate_log(
    log_path: str,
    rig_json: str | None,
    rig_source: str,
    stride: int,
    pairing: str,
    settings: _Settings,
    rule: _Rule,
    solve_every: int,
) -> LogCalibrationResult:
    """Phase 1 on a vehicle log (read, decode, associate, solve); raises
    ``stereonav.InputError`` naming the file or the setting."""

#: ``(accepted ids (A,), accepted NIS (A,), rejected ids (R,), rejected NIS (R,), removed (D,))``.
_UpdateTuple = tuple[_U64, _F64, _U64, _F64, _U64]
#: ``(update, added (K, 2), removed (K, 2), ignored, pending)``; pairs are ``(track, landmark)``.
_FrameTuple = tuple[_UpdateTuple, _U64, _U64, int, int]
#: ``(gate_probability, nis_window, max_consecutive_rejections, covariance_update)``.
_FilterSettings = tuple[float, int, int, str]
#: ``(frames_to_confirm, consistency_probability)``.
_CandidateSettings = tuple[int, float]
#: ``(updates, refused_updates, accepted, rejected, landmarks_added, landmarks_removed,
#: window_observations, window_rejected, window_mean_nis_per_dof, window_nis_bound,
#: nis_too_high, diverged)``.
_HealthTuple = tuple[int, int, int, int, int, int, int, int, "float | None", "float | None", bool, bool]

def filter_defaults() -> tuple[float, int, int, str, int, float]:
    """The defaults ``(gate_probability, nis_window, max_consecutive_rejections,
    covariance_update, frames_to_confirm, consistency_probability)``."""

@final
class Filter:
    """Phase 2, the EKF with the camera in the state (see ``stereonav.Filter``)."""

    def __new__(
        cls,
        rig_json: str,
        rig_source: str,
        start: tuple[_F64, _F64] | None,
        settings: _FilterSettings,
        candidates: _CandidateSettings,
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
    def health(self) -> _HealthTuple: ...
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
#: ``(t_us (F,), phase (F,), pose (F, 3), pose_covariance (F, 3, 3), accepted (F,),
#: rejected (F,), landmarks (F,))``.
_FramesTuple = tuple[_U64, npt.NDArray[np.uint8], _F64, _F64, _U64, _U64, _U64]
#: ``(accepted ids, accepted NIS, rejected ids, added ids, removed ids, rematched (K, 2),
#: solved, switched, no_odometry)``.
_OutcomeTuple = tuple[_U64, _F64, _U64, _U64, _U64, _U64, bool, bool, bool]

def phase_names() -> list[str]:
    """The phase names, in the order of the per-frame phase codes."""

@final
class ReplayResult:
    """A whole log replayed (see ``stereonav.Replay``)."""

    def summary_json(self) -> str:
        """``SUMMARY.json`` as JSON text."""
    @property
    def frames(self) -> _FramesTuple: ...
    @property
    def nis(self) -> tuple[_U64, _U64, _F64]:
        """``(t_us (K,), landmark id (K,), NIS (K,))``."""
    @property
    def camera_history(self) -> tuple[_U64, npt.NDArray[np.uint8], _F64, _F64]:
        """``(t_us (K,), phase (K,), values (K, 10), sigmas (K, 10))``."""
    @property
    def camera(self) -> _CameraTuple: ...
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

def replay(
    log_path: str,
    rig_json: str | None,
    rig_source: str,
    skip_phase1: bool,
    phase1_frames: int | None,
    consider_camera: bool,
) -> ReplayResult:
    """The whole stack on a vehicle log; raises ``stereonav.InputError`` naming the file or
    the setting."""

@final
class Navigator:
    """Both phases of the method fed frame by frame (see ``stereonav.Navigator``)."""

    def __new__(
        cls,
        rig_json: str,
        rig_source: str,
        skip_phase1: bool,
        phase1_frames: int | None,
        consider_camera: bool,
    ) -> Navigator: ...
    def push_odometry(self, t_us: _U64, values: _F64) -> None:
        """Odometry ``(t_us (S,), vx vy vtheta (S, 3))``, sorted, none older than before."""
    def push_frame(self, t_us: int, left: _F64, right: _F64) -> _OutcomeTuple:
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
    def camera_covariance(self) -> _F64: ...
    @property
    def landmarks(self) -> _LandmarkTuple: ...
    @property
    def stats(self) -> list[tuple[str, int]]: ...

_RigTuple = tuple[int, int, list[float], list[str], list[tuple[str, float]], tuple[float, float, float]]

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
    def rig(self) -> _RigTuple | None:
        """The first ``/rig`` message as :func:`load_rig` returns a rig, or None; raises
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
