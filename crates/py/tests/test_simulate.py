"""The simulator from Python: truth as arrays, determinism, the stream decodes, errors."""

from __future__ import annotations

import pathlib

import numpy as np
import pytest

import stereonav

SCENARIOS = pathlib.Path(__file__).resolve().parents[3] / "fixtures" / "scenarios"


def test_paper_experiment_truth_as_arrays() -> None:
    sim = stereonav.simulate(SCENARIOS / "paper-experiment.toml")
    assert sim.name == "paper-experiment" and sim.mode == "fast"
    assert sim.trajectory.dtype == stereonav.TRAJECTORY_DTYPE
    assert sim.landmarks.shape == (5, 3)
    assert len(sim.trajectory) == len(sim.visible) > 100
    assert sim.visible.min() >= 2
    assert np.all(np.diff(sim.trajectory["t_us"].astype(np.int64)) > 0)
    # The path runs along X and back: y stays near 0, x spans metres.
    assert np.ptp(sim.trajectory["x"]) > 1.0 and np.abs(sim.trajectory["y"]).max() < 0.05
    # Odometry at 100 Hz, the truth alongside.
    dt = np.diff(sim.odometry["t_us"].astype(np.int64))
    assert np.all(dt == 10_000)
    assert np.array_equal(sim.odometry["t_us"], sim.odometry_truth["t_us"])
    # The nominal rig differs from the true camera (that is what phase 1 is for).
    rig_truth = sim.truth()
    assert set(rig_truth) >= {"camera", "landmarks", "trajectory"}
    assert "baseline" in sim.rig_toml


def test_same_seed_same_bytes() -> None:
    a = stereonav.simulate(SCENARIOS / "paper-experiment.toml", seed=3)
    b = stereonav.simulate(SCENARIOS / "paper-experiment.toml", seed=3)
    c = stereonav.simulate(SCENARIOS / "paper-experiment.toml", seed=4)
    assert a.stream == b.stream and a.seed == 3
    assert a.stream != c.stream


def test_the_stream_decodes_to_one_frame_per_stereo_frame() -> None:
    sim = stereonav.simulate(SCENARIOS / "paper-square.toml")
    decoder = stereonav.StreamDecoder()
    frames = decoder.push(sim.stream) + decoder.finish()
    assert [f.t_us for f in frames] == sim.trajectory["t_us"].tolist()
    assert decoder.stats.corrupt == 0


def test_write_log(tmp_path: pathlib.Path) -> None:
    sim = stereonav.simulate(SCENARIOS / "paper-experiment.toml")
    out = tmp_path / "run.mcap"
    sim.write_log(out)
    assert out.read_bytes()[:8] == b"\x89MCAP0\r\n"


def test_bad_scenarios_raise(tmp_path: pathlib.Path) -> None:
    with pytest.raises(stereonav.InputError, match="missing.toml"):
        stereonav.simulate(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("seed = 'nine'\n")
    with pytest.raises(ValueError, match="bad.toml"):
        stereonav.simulate(bad)
    with pytest.raises(TypeError):
        stereonav.simulate(SCENARIOS / "paper-experiment.toml", seed=-1)
