"""Stubs of the native module ``stereonav._native`` (``crates/py/src/lib.rs``).

Call the typed wrappers in :mod:`stereonav` instead; these functions check less.
"""

from typing import Final, final

import numpy as np
import numpy.typing as npt

__all__ = [
    "__version__",
    "FEATURE_RECORD_BYTES",
    "SimRun",
    "StreamDecoder",
    "simulate",
    "camera_parameter_names",
    "load_rig",
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
