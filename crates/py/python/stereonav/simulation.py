"""The seeded simulator of the published scenarios, with its ground truth as NumPy arrays."""

from __future__ import annotations

import json
import os
from typing import Any, Optional, Union

import numpy as np
import numpy.typing as npt

from . import _native
from ._errors import InputTypeError
from .rig import Camera

__all__ = ["ODOMETRY_DTYPE", "TRAJECTORY_DTYPE", "Simulation", "simulate"]

#: One odometry sample: ``t_us`` (``<u8``), ``vx``, ``vy`` (m/s), ``vtheta`` (rad/s).
ODOMETRY_DTYPE = np.dtype([("t_us", "<u8"), ("vx", "<f8"), ("vy", "<f8"), ("vtheta", "<f8")])
#: One pose per stereo frame: ``t_us`` (``<u8``), ``x``, ``y`` (m), ``theta`` (rad).
TRAJECTORY_DTYPE = np.dtype([("t_us", "<u8"), ("x", "<f8"), ("y", "<f8"), ("theta", "<f8")])


def _odometry(raw: npt.NDArray[np.float64]) -> npt.NDArray[np.void]:
    out = np.zeros(len(raw), dtype=ODOMETRY_DTYPE)
    out["t_us"] = raw[:, 0].astype(np.uint64)
    out["vx"], out["vy"], out["vtheta"] = raw[:, 1], raw[:, 2], raw[:, 3]
    return out


class Simulation:
    """One simulated run: the vehicle's sensor data and the truth behind it.

    Attributes
    ----------
    name, mode : str
        Scenario name; ``"fast"`` or ``"rendered"``.
    seed : int
        The seed used (same seed, same bytes).
    camera : Camera
        The true camera parameters.
    rig_toml : str
        The nominal rig file a user of this vehicle has (it differs from the truth).
    trajectory : numpy.ndarray of TRAJECTORY_DTYPE, shape (F,)
        True pose at each stereo frame.
    landmarks : numpy.ndarray of float64, shape (N, 3)
        True lamp positions in the world frame; row ``i`` is landmark id ``i``.
    visible : numpy.ndarray of uint64, shape (F,)
        Lamps in view at each frame.
    odometry, odometry_truth : numpy.ndarray of ODOMETRY_DTYPE, shape (S,)
        The odometry as logged (noisy) and the true velocities at the same instants.
    stream : bytes
        The camera board's byte stream as received (with any link faults).
    """

    def __init__(self, native: Any) -> None:
        self._native = native
        self.name: str = native.name
        self.mode: str = native.mode
        self.seed: int = native.seed
        self.camera = Camera.from_array(native.camera)
        self.rig_toml: str = native.rig_toml
        poses = native.frame_poses
        self.trajectory = np.zeros(len(poses), dtype=TRAJECTORY_DTYPE)
        self.trajectory["t_us"] = native.frame_t_us
        self.trajectory["x"], self.trajectory["y"], self.trajectory["theta"] = poses.T
        self.landmarks: npt.NDArray[np.float64] = native.landmarks
        self.visible: npt.NDArray[np.uint64] = native.visible
        self.odometry = _odometry(native.odometry)
        self.odometry_truth = _odometry(native.odometry_truth)

    @property
    def stream(self) -> bytes:
        """The board's byte stream as received (all chunks in order)."""
        return bytes(self._native.stream)

    def truth(self) -> dict[str, Any]:
        """The ground truth as a dict (trajectory, landmarks, true C), as ``--truth`` writes."""
        result: dict[str, Any] = json.loads(self._native.truth_json())
        return result

    def write_log(self, path: Union[str, os.PathLike[str]]) -> None:
        """Write the vehicle log (MCAP, ``vehicle-interfaces.md`` section 4)."""
        self._native.write_log(os.fspath(path))


def simulate(
    scenario: Union[str, os.PathLike[str]], *, rendered: bool = False, seed: Optional[int] = None
) -> Simulation:
    """Simulate a scenario file (``fixtures/scenarios/*.toml``).

    Parameters
    ----------
    scenario : path
        The scenario TOML.
    rendered : bool
        Draw 8-bit images and run the board's detector on them instead of projecting lamps.
    seed : int, optional
        Overrides the scenario's seed.

    Raises
    ------
    InputError
        (a ``ValueError``) the scenario or its rig file is missing or wrong; the message
        names the file, the key and the problem.
    """
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
        raise InputTypeError(f"seed must be a non-negative int, got {seed!r}")
    return Simulation(_native.simulate(os.fspath(scenario), bool(rendered), seed))
