"""The phase-2 Monte Carlo evaluation from Python: shapes and consistency of a small run,
outliers, determinism, bad input."""

from __future__ import annotations

import dataclasses
import functools
import pathlib

import numpy as np
import pytest

import stereonav
from stereonav import Banded, InputError, InputTypeError, MonteCarloSummary, monte_carlo

SCENARIOS = pathlib.Path(__file__).resolve().parents[3] / "fixtures" / "scenarios"
PAPER = SCENARIOS / "paper-experiment.toml"
RUNS = 5
FRAMES = 300


@functools.lru_cache(maxsize=None)
def small() -> MonteCarloSummary:
    return monte_carlo(PAPER, RUNS, max_frames=FRAMES)


def test_a_small_monte_carlo_has_consistent_shapes() -> None:
    summary = small()
    runs = summary.runs
    assert summary.scenario == str(PAPER)
    assert len(runs) == RUNS
    np.testing.assert_array_equal(runs.seed, np.arange(RUNS, dtype=np.uint64))
    assert runs.seed.dtype == np.uint64
    np.testing.assert_array_equal(runs.frames, [FRAMES] * RUNS)
    for name in ("landmark_rms", "mean_nis"):
        array = getattr(runs, name)
        assert array.shape == (RUNS,) and array.dtype == np.float64, name
    for name in ("landmarks", "lamps_missing", "accepted", "rejected", "outliers", "outliers_accepted", "refused_updates"):
        array = getattr(runs, name)
        assert array.shape == (RUNS,) and array.dtype == np.uint64, name
    for name in ("within_3_sigma", "healthy"):
        array = getattr(runs, name)
        assert array.shape == (RUNS,) and array.dtype == np.bool_, name
    # One NEES per frame after the first, for every run.
    assert runs.pose_nees.shape == runs.state_nees.shape == runs.state_nees_dof.shape == (RUNS, FRAMES - 1)
    assert runs.state_nees_dof.dtype == np.uint64
    assert np.all(np.isfinite(runs.pose_nees)) and np.all(runs.pose_nees >= 0.0)
    # The state NEES covers the pose, every mapped lamp and the baseline: 4 before any lamp
    # is confirmed, 3 + 3 * 5 + 1 = 19 once all are.
    assert runs.state_nees_dof.min() == 4 and runs.state_nees_dof.max() == 19
    assert np.all((runs.state_nees_dof - 4) % 3 == 0)
    assert np.all(np.diff(runs.state_nees_dof.astype(np.int64), axis=1) >= 0)
    # The camera: only the baseline, its truth that of the scenario.
    assert runs.camera_parameters == ("baseline",)
    for name in ("camera_value", "camera_truth", "camera_error", "camera_sigma"):
        array = getattr(runs, name)
        assert array.shape == (RUNS, 1) and array.dtype == np.float64, name
    np.testing.assert_array_equal(runs.camera_truth, 0.1164)
    np.testing.assert_array_equal(runs.camera_error, runs.camera_value - runs.camera_truth)
    assert np.all(runs.camera_sigma > 0.0) and np.all(runs.camera_sigma < 0.006)
    assert runs.pose_error.shape == (RUNS, 3)
    # Results are read-only and frozen.
    with pytest.raises(ValueError):
        runs.landmark_rms[0] = 0.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        summary.healthy = 0  # type: ignore[misc]


def test_a_small_monte_carlo_is_sane() -> None:
    summary = small()
    runs = summary.runs
    # Every run healthy, its five lamps mapped to a few millimetres, the baseline within
    # half a millimetre, no refused update.
    assert runs.healthy.all() and summary.healthy == RUNS
    assert summary.within_3_sigma == int(runs.within_3_sigma.sum())
    np.testing.assert_array_equal(runs.landmarks, 5)
    np.testing.assert_array_equal(runs.lamps_missing, 0)
    assert np.all(runs.landmark_rms < 0.01)
    assert np.all(np.abs(runs.camera_error) < 0.0005)
    np.testing.assert_array_equal(runs.refused_updates, 0)
    np.testing.assert_array_equal(runs.outliers, 0)
    assert np.all(runs.accepted > 900)
    # NIS of a consistent filter: 4 dof.
    assert np.all((runs.mean_nis > 3.0) & (runs.mean_nis < 5.0))
    # The banded statistics: each a value with a band around the consistent value.
    for banded, expected in ((summary.pose_nees, 3.0), (summary.state_nees_per_dof, 1.0), (summary.nis, 4.0)):
        assert isinstance(banded, Banded)
        assert banded.low < expected < banded.high
        assert np.isfinite(banded.value) and banded.value > 0.0
        assert banded.inside == (banded.low <= banded.value <= banded.high)
    assert 0.0 <= summary.pose_nees_frames_inside <= 1.0
    assert 0.0 <= summary.state_nees_frames_inside <= 1.0
    # The summary's means are those of the per-run arrays.
    assert summary.pose_nees.value == pytest.approx(runs.pose_nees.mean(), rel=1e-9)
    per_dof = runs.state_nees.sum() / runs.state_nees_dof.sum()
    assert summary.state_nees_per_dof.value == pytest.approx(per_dof, rel=1e-9)
    mean_nis = (runs.mean_nis * runs.accepted).sum() / runs.accepted.sum()
    assert summary.nis.value == pytest.approx(mean_nis, rel=1e-9)


def test_outliers_are_mixed_in_and_gated() -> None:
    summary = monte_carlo(PAPER, 2, first_seed=10, outlier_fraction=0.05, max_frames=200)
    runs = summary.runs
    np.testing.assert_array_equal(runs.seed, [10, 11])
    assert np.all(runs.outliers > 0)
    assert np.all(runs.outliers_accepted <= runs.outliers // 10)
    # Outliers on landmarks in the map are rejected by the gate; those on tracks still
    # waiting for confirmation only restart them (the gate never sees them).
    assert np.all(runs.rejected >= 0.8 * runs.outliers)
    assert np.all(runs.rejected <= runs.outliers + runs.accepted // 100)
    assert runs.healthy.all()


def test_the_same_seeds_give_the_same_runs() -> None:
    again = monte_carlo(PAPER, 2, max_frames=FRAMES)
    first = small()
    np.testing.assert_array_equal(again.runs.landmark_rms, first.runs.landmark_rms[:2])
    np.testing.assert_array_equal(again.runs.pose_nees, first.runs.pose_nees[:2])


@pytest.mark.parametrize(
    ("arguments", "keywords", "error", "message"),
    [
        ((PAPER, 0), {}, InputError, "runs is 0"),
        ((PAPER, 2.5), {}, InputTypeError, "runs must be an int"),
        ((PAPER, 1), {"first_seed": -1}, InputError, "first_seed is -1"),
        ((PAPER, 1), {"outlier_fraction": 1.5}, InputError, "outlier_fraction is 1.5"),
        ((PAPER, 1), {"max_frames": 0}, InputError, "max_frames is 0"),
        ((SCENARIOS / "no-such.toml", 1), {}, InputError, "no-such.toml"),
        ((3, 1), {}, InputTypeError, "scenario must be a str or os.PathLike"),
    ],
)
def test_bad_input_raises(arguments: tuple[object, ...], keywords: dict[str, object], error: type, message: str) -> None:
    with pytest.raises(error, match=message):
        monte_carlo(*arguments, **keywords)  # type: ignore[arg-type]


def test_exports() -> None:
    assert stereonav.monte_carlo is monte_carlo
    assert stereonav.MonteCarloRuns is type(small().runs)
