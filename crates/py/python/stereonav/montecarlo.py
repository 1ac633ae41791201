"""Seeded Monte Carlo evaluation of phase 2 (crate ``eval``) against the simulator's truth.

Each run simulates a scenario (fast mode) with its own seed and steps a :class:`Filter` (from
the rig's priors) through it with the logged odometry and, frame by frame, the lamps'
stereo measurements keyed by the simulator's lamp ids: association is perfect on purpose, so
that what is measured is the filter. Gross outliers can be mixed in to exercise the gate.
Every frame records the pose NEES and the full-state NEES (pose, mapped lamps, estimated
camera parameters) with its degrees of freedom; each run ends with the landmark and camera
errors and their sigmas.

The summary gives the usual consistency statistics (Bar-Shalom, Li and Kirubarajan,
section 5.4): with ``R`` runs, ``R`` times the run-averaged NEES at a frame is chi-square with
``R`` times its dof, which gives the 95 % band of the average; likewise the mean NIS of the
accepted observations (4 dof).
"""

from __future__ import annotations

import dataclasses
import os
from typing import Optional, Union, final

import numpy as np
import numpy.typing as npt

from . import _native
from ._arrays import readonly as _readonly
from ._errors import InputError, InputTypeError
from .calibration import _count, _describe, _number

__all__ = ["Banded", "MonteCarloRuns", "MonteCarloSummary", "monte_carlo"]

_F64 = npt.NDArray[np.float64]
_U64 = npt.NDArray[np.uint64]
_BOOL = npt.NDArray[np.bool_]


@final
@dataclasses.dataclass(frozen=True)
class Banded:
    """A statistic with its two-sided 95 % chi-square band (what a consistent filter gives)."""

    #: The statistic.
    value: float
    #: Lower end of its 95 % band.
    low: float
    #: Upper end of its 95 % band.
    high: float

    @property
    def inside(self) -> bool:
        """Whether the value lies inside its band."""
        return self.low <= self.value <= self.high


@final
@dataclasses.dataclass(frozen=True, eq=False)
class MonteCarloRuns:
    """Per-run results: row ``i`` of every array is the run of seed ``seed[i]``.

    ``R`` is the number of runs, ``F`` the frames of the longest run after the first frame
    (shorter rows are padded with NaN, or 0 for ``state_nees_dof``), ``m`` the estimated
    camera parameters. Arrays are read-only.

    Attributes
    ----------
    seed : numpy.ndarray of uint64, shape (R,)
    frames : numpy.ndarray of uint64, shape (R,)
        Frames processed.
    landmark_rms : numpy.ndarray of float64, shape (R,)
        RMS of the mapped lamps' 3-D position errors at the end, metres.
    landmarks : numpy.ndarray of uint64, shape (R,)
        Lamps in the map at the end.
    lamps_missing : numpy.ndarray of uint64, shape (R,)
        Lamps seen but never mapped.
    camera_parameters : tuple of str
        The ``m`` estimated camera parameters, the columns of the camera arrays.
    camera_value, camera_truth, camera_error, camera_sigma : numpy.ndarray of float64, shape (R, m)
        Each estimated parameter at the end: estimate, truth, estimate minus truth, 1-sigma.
    within_3_sigma : numpy.ndarray of bool, shape (R,)
        Every mapped lamp inside its 3-sigma ellipsoid and every camera parameter within
        3 sigma.
    healthy : numpy.ndarray of bool, shape (R,)
        The state stayed finite and the covariance positive definite at every frame.
    pose_nees : numpy.ndarray of float64, shape (R, F)
        Pose NEES (3 dof) at each frame after the first.
    state_nees : numpy.ndarray of float64, shape (R, F)
        Full-state NEES at each frame after the first ...
    state_nees_dof : numpy.ndarray of uint64, shape (R, F)
        ... with its degrees of freedom (3 + 3 mapped lamps + m).
    mean_nis : numpy.ndarray of float64, shape (R,)
        Mean NIS of the run's accepted observations (4 dof: near 4); NaN without any.
    accepted, rejected : numpy.ndarray of uint64, shape (R,)
        Observations accepted and rejected by the gate (outliers included).
    outliers, outliers_accepted : numpy.ndarray of uint64, shape (R,)
        Gross outliers mixed in, and those the gate let through.
    refused_updates : numpy.ndarray of uint64, shape (R,)
        Updates the filter refused.
    pose_error : numpy.ndarray of float64, shape (R, 3)
        Final pose error ``(dx, dy, dtheta)``, metres and radians.
    """

    seed: _U64
    frames: _U64
    landmark_rms: _F64
    landmarks: _U64
    lamps_missing: _U64
    camera_parameters: tuple[str, ...]
    camera_value: _F64
    camera_truth: _F64
    camera_error: _F64
    camera_sigma: _F64
    within_3_sigma: _BOOL
    healthy: _BOOL
    pose_nees: _F64
    state_nees: _F64
    state_nees_dof: _U64
    mean_nis: _F64
    accepted: _U64
    rejected: _U64
    outliers: _U64
    outliers_accepted: _U64
    refused_updates: _U64
    pose_error: _F64

    def __len__(self) -> int:
        """The number of runs."""
        return len(self.seed)


@final
@dataclasses.dataclass(frozen=True, eq=False)
class MonteCarloSummary:
    """Many seeded runs of phase 2 on one scenario (:func:`monte_carlo`).

    Attributes
    ----------
    scenario : str
        The scenario file.
    runs : MonteCarloRuns
        Every run's results.
    pose_nees : Banded
        Pose NEES averaged over runs and frames (3 for a consistent filter).
    pose_nees_frames_inside : float
        Fraction of frames whose run-averaged pose NEES lies inside its 95 % band.
    state_nees_per_dof : Banded
        Full-state NEES per degree of freedom, averaged over runs and frames (near 1).
    state_nees_frames_inside : float
        Fraction of frames whose run-summed full-state NEES lies inside its 95 % band.
    nis : Banded
        Mean NIS of every accepted observation of every run (4 dof: near 4).
    within_3_sigma : int
        Runs with every mapped lamp and camera parameter inside 3 sigma.
    healthy : int
        Runs whose state stayed finite and covariance positive definite throughout.
    """

    scenario: str
    runs: MonteCarloRuns
    pose_nees: Banded
    pose_nees_frames_inside: float
    state_nees_per_dof: Banded
    state_nees_frames_inside: float
    nis: Banded
    within_3_sigma: int
    healthy: int


def monte_carlo(
    scenario: Union[str, "os.PathLike[str]"],
    runs: int = 20,
    *,
    first_seed: int = 0,
    outlier_fraction: float = 0.0,
    max_frames: Optional[int] = None,
) -> MonteCarloSummary:
    """Run phase 2 on ``runs`` seeded simulations of a scenario and summarise them.

    The runs go in Rust, one after the other, with the GIL released.

    Parameters
    ----------
    scenario : str or os.PathLike
        The scenario TOML (``fixtures/scenarios/*.toml``).
    runs : int
        Number of runs, at least 1; run ``i`` has seed ``first_seed + i``.
    first_seed : int, keyword-only
        The first seed, ``>= 0``.
    outlier_fraction : float, keyword-only
        Fraction of the lamp measurements replaced by gross outliers (each coordinate moved
        5 to 40 pixels), in ``[0, 1]``.
    max_frames : int, optional, keyword-only
        Frames to run, at least 1 (default: the whole scenario).

    Returns
    -------
    MonteCarloSummary

    Raises
    ------
    InputTypeError
        (a ``TypeError``) an argument has the wrong type.
    InputError
        (a ``ValueError``) the scenario or its rig file is missing or wrong (the message
        names the file and the key), or a value is out of range.
    """
    if not isinstance(scenario, (str, os.PathLike)):
        raise InputTypeError(f"scenario must be a str or os.PathLike, got {_describe(scenario)}")
    path = os.fspath(scenario)
    if not isinstance(path, str):
        raise InputTypeError(f"scenario must be a str path, got {_describe(path)}")
    count = _count("runs", runs, 1)
    seed = _count("first_seed", first_seed, 0)
    fraction = _number("outlier_fraction", outlier_fraction)
    if not 0.0 <= fraction <= 1.0:
        raise InputError(f"outlier_fraction is {fraction}, expected a fraction in [0, 1]")
    frames = None if max_frames is None else _count("max_frames", max_frames, 1)
    native = _native.monte_carlo(path, count, seed, fraction, frames)
    value, truth = native.camera_value, native.camera_truth
    result = MonteCarloRuns(
        seed=_readonly(native.seeds),
        frames=_readonly(native.frames),
        landmark_rms=_readonly(native.landmark_rms),
        landmarks=_readonly(native.landmarks),
        lamps_missing=_readonly(native.lamps_missing),
        camera_parameters=tuple(native.camera_parameters),
        camera_value=_readonly(value),
        camera_truth=_readonly(truth),
        camera_error=_readonly(value - truth),
        camera_sigma=_readonly(native.camera_sigma),
        within_3_sigma=_readonly(native.within_3_sigma),
        healthy=_readonly(native.healthy),
        pose_nees=_readonly(native.pose_nees),
        state_nees=_readonly(native.state_nees),
        state_nees_dof=_readonly(native.state_nees_dof),
        mean_nis=_readonly(native.mean_nis),
        accepted=_readonly(native.accepted),
        rejected=_readonly(native.rejected),
        outliers=_readonly(native.outliers),
        outliers_accepted=_readonly(native.outliers_accepted),
        refused_updates=_readonly(native.refused_updates),
        pose_error=_readonly(native.pose_error),
    )
    return MonteCarloSummary(
        scenario=path,
        runs=result,
        pose_nees=Banded(*native.pose_nees_band),
        pose_nees_frames_inside=native.pose_nees_frames_inside,
        state_nees_per_dof=Banded(*native.state_nees_per_dof_band),
        state_nees_frames_inside=native.state_nees_frames_inside,
        nis=Banded(*native.nis_band),
        within_3_sigma=native.within_3_sigma_count,
        healthy=native.healthy_count,
    )
