"""Phase 1 (self-calibration) from Python: frame pairs as arrays, the batch solve against the
simulator's truth, the observability report, the incremental calibrator, bad input."""

from __future__ import annotations

import dataclasses
import functools
import pathlib
import re

import numpy as np
import pytest

import stereonav
from sim_labels import lamp_measurements
from stereonav import (
    CAMERA_PARAMETERS,
    MEASUREMENT_DTYPE,
    MOTION_DTYPE,
    OBSERVATION_DTYPE,
    Calibration,
    SelfCalibrator,
    calibrate,
    frame_pairs,
    integrate_odometry,
)

SCENARIOS = pathlib.Path(__file__).resolve().parents[3] / "fixtures" / "scenarios"
PAPER = SCENARIOS / "paper-calibration.toml"
#: Frames from the first frame of a pair to its second (2 s at 20 Hz), as in the sim crate's
#: phase-1 tests: long pairs see much motion per pixel of noise.
STRIDE = 40


def pairs_by_lamp(
    measurements: np.ndarray, odometry: np.ndarray, stride: int
) -> tuple[np.ndarray, np.ndarray]:
    """Frame pairs formed here, in Python: disjoint pairs ``stride`` frames apart, the lamps
    seen in both frames by id, the odometry integrated between them."""
    times = np.unique(measurements["t_us"])
    starts = np.arange(0, len(times) - stride, stride + 1)
    t0, t1 = times[starts], times[starts + stride]
    motions = integrate_odometry(odometry, t0, t1)
    rows = []
    for p, (a, b) in enumerate(zip(t0, t1)):
        first = {int(m["id"]): m for m in measurements[measurements["t_us"] == a]}
        second = {int(m["id"]): m for m in measurements[measurements["t_us"] == b]}
        for lamp in sorted(first.keys() & second.keys()):
            m0, m1 = first[lamp], second[lamp]
            rows.append((p, m0["uL"], m0["vL"], m0["uR"], m0["vR"], m1["uL"], m1["vL"], m1["uR"], m1["vR"]))
    return np.array(rows, dtype=OBSERVATION_DTYPE), motions


@functools.lru_cache(maxsize=None)
def paper_data(stride: int = STRIDE) -> tuple[stereonav.Simulation, np.ndarray, np.ndarray]:
    sim = stereonav.simulate(PAPER)
    observations, motions = pairs_by_lamp(lamp_measurements(sim), sim.odometry, stride)
    return sim, observations, motions


def paper_rig() -> stereonav.RigConfig:
    return stereonav.load_rig(SCENARIOS / "paper-calibration.rig.toml")


def test_paper_calibration_against_the_truth() -> None:
    sim, observations, motions = paper_data()
    rig = paper_rig()
    assert len(motions) > 30 and len(observations) > 3 * len(motions)
    cal = calibrate(observations, motions, rig)
    assert isinstance(cal, Calibration)
    assert cal.status == "converged" and cal.converged
    assert cal.observability.unobservable == ()
    assert cal.residuals == len(observations)
    # The baseline within 1 mm, f within 3 sigma; the nominal values were far worse.
    assert abs(cal.camera.baseline - sim.camera.baseline) < 0.001
    assert abs(cal.camera.f - sim.camera.f) <= 3 * cal.sigmas["f"]
    assert abs(cal.camera.f - sim.camera.f) < abs(rig.nominal.f - sim.camera.f) / 5
    # Unestimated parameters stay nominal and have no uncertainty.
    assert cal.camera.cx == rig.nominal.cx and cal.camera.mount_pitch == rig.nominal.mount_pitch
    assert set(cal.sigmas) == set(CAMERA_PARAMETERS)
    assert cal.sigmas["cx"] == 0.0 and cal.sigmas["f"] > 0.0
    # Covariance: 10 x 10 in CAMERA_PARAMETERS order, symmetric, zero outside the estimate.
    f, b = CAMERA_PARAMETERS.index("f"), CAMERA_PARAMETERS.index("baseline")
    assert cal.covariance.shape == (10, 10) and cal.covariance.dtype == np.float64
    np.testing.assert_allclose(cal.covariance, cal.covariance.T)
    assert cal.covariance[f, f] == pytest.approx(cal.sigmas["f"] ** 2)
    assert np.count_nonzero(cal.covariance) == 4 and cal.covariance[f, b] != 0.0
    assert 0.3 < cal.reduced_chi2 < 3.0
    # The observability report: both estimated parameters, with their sigmas.
    report = cal.observability
    assert [p.name for p in report.params] == ["f", "baseline"]
    assert report["f"].observable and report["f"].reason is None
    assert report["f"].posterior_sigma < report["f"].prior_sigma == rig.prior["f"]
    assert 0.0 < report["baseline"].data_sigma < np.inf
    assert report.max_correlation is not None
    assert {report.max_correlation.first, report.max_correlation.second} == {"f", "baseline"}
    assert -1.0 <= report.max_correlation.value <= 1.0
    assert report.eigenvalues.shape == (2,) and np.all(np.diff(report.eigenvalues) >= 0)


def test_history_starts_nominal_and_ends_at_the_estimate() -> None:
    _, observations, motions = paper_data()
    rig = paper_rig()
    cal = calibrate(observations, motions, rig)
    assert cal.history.ndim == 2 and cal.history.shape[1] == len(CAMERA_PARAMETERS)
    assert 2 <= len(cal.history) <= cal.iterations + 1
    np.testing.assert_array_equal(cal.history[0], rig.nominal.to_array())
    np.testing.assert_array_equal(cal.history[-1], cal.camera.to_array())
    # A start of the caller's choice, and an iteration limit that stops early.
    start = dataclasses.replace(rig.nominal, f=710.0)
    one = calibrate(observations, motions, rig, start=start, max_iterations=1)
    assert one.status == "max_iterations" and one.iterations == 1
    assert one.history[0][CAMERA_PARAMETERS.index("f")] == 710.0
    # Results are read-only.
    with pytest.raises(ValueError):
        cal.covariance[0, 0] = 1.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        cal.status = "stalled"  # type: ignore[misc]


def test_frame_pairs_matches_pairs_formed_in_python() -> None:
    sim = stereonav.simulate(PAPER)
    measurements = lamp_measurements(sim)
    expected_obs, expected_motions = pairs_by_lamp(measurements, sim.odometry, STRIDE)
    observations, motions = frame_pairs(measurements, sim.odometry, stride=STRIDE)
    assert observations.dtype == OBSERVATION_DTYPE and motions.dtype == MOTION_DTYPE
    np.testing.assert_array_equal(observations, expected_obs)
    np.testing.assert_array_equal(motions, expected_motions)
    # Shuffled rows make the same pairs (frames by time, landmarks by id).
    shuffled = measurements[np.random.default_rng(1).permutation(len(measurements))]
    again, _ = frame_pairs(shuffled, sim.odometry, stride=STRIDE)
    np.testing.assert_array_equal(again, observations)


def test_integrate_odometry_matches_constant_velocities() -> None:
    odometry = np.zeros(11, dtype=stereonav.ODOMETRY_DTYPE)
    odometry["t_us"] = 1_000_000 + 10_000 * np.arange(11)
    odometry["vx"] = 0.5
    motions = integrate_odometry(odometry, [1_000_000, 1_050_000], [1_100_000, 1_050_000])
    assert motions.dtype == MOTION_DTYPE
    assert motions["dx"] == pytest.approx([0.05, 0.0])
    assert motions["dt_s"] == pytest.approx([0.1, 0.0])
    assert motions["samples"].tolist() == [10, 0]
    assert motions["t_us"].tolist() == [1_100_000, 1_050_000]


def upward_scenario(tmp_path: pathlib.Path) -> pathlib.Path:
    """paper-calibration with the head looking straight up (pitch 0), truth and rig alike."""
    rig_text = (SCENARIOS / "paper-calibration.rig.toml").read_text()
    rig_text, n = re.subn(r"(?m)^pitch\s*=.*$", "pitch = 0.0", rig_text)
    assert n == 1
    (tmp_path / "up.rig.toml").write_text(rig_text)
    text = PAPER.read_text()
    text, n = re.subn(r"pitch_deg\s*=\s*[-+0-9.eE]+", "pitch_deg = 0.0", text)
    assert n == 1
    text, n = re.subn(r'(?m)^rig\s*=.*$', 'rig = "up.rig.toml"', text)
    assert n == 1
    path = tmp_path / "up.toml"
    path.write_text(text)
    return path


def test_upward_head_cannot_give_f_but_gives_the_baseline(tmp_path: pathlib.Path) -> None:
    sim = stereonav.simulate(upward_scenario(tmp_path))
    rig_path = tmp_path / "up.rig.toml"
    assert stereonav.load_rig(rig_path).nominal.mount_pitch == 0.0
    observations, motions = frame_pairs(lamp_measurements(sim), sim.odometry, stride=STRIDE)
    cal = calibrate(observations, motions, rig_path)
    f, baseline = cal.observability["f"], cal.observability["baseline"]
    assert not f.observable
    assert f.reason is not None and "f is not observable" in f.reason and "straight up" in f.reason
    assert cal.observability.unobservable == ("f",)
    assert cal.camera.f == stereonav.load_rig(rig_path).nominal.f, "held at nominal"
    assert cal.sigmas["f"] == 0.0
    assert baseline.observable and baseline.reason is None
    assert abs(cal.camera.baseline - sim.camera.baseline) < 0.002
    with pytest.raises(KeyError):
        cal.observability["cx"]


def test_incremental_calibration_hands_over() -> None:
    sim, observations, motions = paper_data(10)
    rig = paper_rig()
    calibrator = SelfCalibrator(rig, solve_every=10, min_pairs=40)
    assert calibrator.latest is None and calibrator.handover is None
    solves = 0
    for p in range(len(motions)):
        result = calibrator.add_pair(observations[observations["pair"] == p], motions[p])
        solves += result is not None
        assert (result is not None) == ((p + 1) % 10 == 0)
    assert calibrator.pairs == len(motions) and solves == len(motions) // 10
    history = calibrator.history
    assert history.t_us.dtype == np.uint64 and history.t_us.shape == (solves,)
    assert history.values.shape == history.sigmas.shape == (solves, 10)
    assert np.all(np.diff(history.t_us.astype(np.int64)) > 0)
    hand = calibrator.handover
    assert hand is not None, f"no hand-over after {len(motions)} pairs"
    assert hand.t_us in history.t_us.tolist()
    assert hand.t_us >= motions["t_us"][40 - 1]
    assert abs(hand.camera.baseline - sim.camera.baseline) < 0.0015
    assert abs(hand.camera.f - sim.camera.f) <= 3 * hand.sigmas["f"]
    assert hand.covariance.shape == (10, 10)
    assert hand.observability.unobservable == ()
    latest = calibrator.latest
    assert latest is not None
    np.testing.assert_array_equal(history.values[-1], latest.camera.to_array())
    # The same pairs all at once trigger the same solves.
    bulk = SelfCalibrator(rig, solve_every=10, min_pairs=40)
    assert bulk.add_pairs(observations, motions) == solves
    np.testing.assert_array_equal(bulk.history.values, history.values)


def test_no_pairs_give_the_nominal_camera() -> None:
    rig = paper_rig()
    cal = calibrate(np.zeros(0, OBSERVATION_DTYPE), np.zeros(0, MOTION_DTYPE), rig)
    assert cal.status == "no_data" and cal.residuals == 0
    assert cal.camera == rig.nominal
    assert cal.history.shape == (1, 10)


# --- Bad input -----------------------------------------------------------------------------


def small_data() -> tuple[np.ndarray, np.ndarray]:
    _, observations, motions = paper_data()
    return observations[observations["pair"] < 3].copy(), motions[:3].copy()


def test_wrong_types_and_missing_fields_name_the_field() -> None:
    observations, motions = small_data()
    rig = paper_rig()
    plain = np.zeros((4, 9))
    with pytest.raises(stereonav.InputTypeError, match="observations must be a NumPy structured array"):
        calibrate(plain, motions, rig)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="motions must be"):
        calibrate(observations, [(1, 0.0, 0.0, 0.0, 0.1, 1)], rig)  # type: ignore[arg-type]
    names = [n for n in OBSERVATION_DTYPE.names or () if n != "vR1"]
    missing = np.zeros(3, dtype=[(n, "<f8") for n in names])
    with pytest.raises(stereonav.InputTypeError, match="no field 'vR1'"):
        calibrate(missing, motions, rig)
    text = np.zeros(3, dtype=[("pair", "<u4"), ("uL0", "U4")] + [(n, "<f8") for n in names[2:]] + [("vR1", "<f8")])
    with pytest.raises(stereonav.InputTypeError, match="field 'uL0' has dtype <U4"):
        calibrate(text, motions, rig)
    floats_pair = np.zeros(3, dtype=[(n, "<f8") for n in OBSERVATION_DTYPE.names or ()])
    with pytest.raises(stereonav.InputTypeError, match="field 'pair'"):
        calibrate(floats_pair, motions, rig)
    with pytest.raises(stereonav.InputError, match=r"shape \(2, 3\)"):
        calibrate(np.zeros((2, 3), OBSERVATION_DTYPE), motions, rig)
    with pytest.raises(stereonav.InputTypeError, match="rig must be"):
        calibrate(observations, motions, 42)  # type: ignore[arg-type]
    with pytest.raises(stereonav.InputTypeError, match="max_iterations"):
        calibrate(observations, motions, rig, max_iterations=2.5)  # type: ignore[arg-type]
    with pytest.raises(stereonav.InputTypeError, match="huber"):
        calibrate(observations, motions, rig, huber="3")  # type: ignore[arg-type]


def test_bad_values_name_the_row() -> None:
    observations, motions = small_data()
    rig = paper_rig()
    bad = observations.copy()
    bad["uL1"][2] = np.nan
    with pytest.raises(stereonav.InputError, match=r"observations\[2\] uL1 is NaN"):
        calibrate(bad, motions, rig)
    bad = motions.copy()
    bad["dtheta"][1] = np.inf
    with pytest.raises(ValueError, match=r"motions\[1\] dtheta is inf"):
        calibrate(observations, bad, rig)
    bad = motions.copy()
    bad["dt_s"][0] = -0.1
    with pytest.raises(stereonav.InputError, match=r"motions\[0\] dt_s is -0.1"):
        calibrate(observations, bad, rig)
    bad = observations.copy()
    bad["pair"][1] = 3
    with pytest.raises(stereonav.InputError, match=r"observations\[1\] pair is 3, but motions has 3 rows"):
        calibrate(bad, motions, rig)
    signed = np.zeros(len(observations), dtype=[("pair", "<i8")] + [(n, "<f8") for n in OBSERVATION_DTYPE.names[1:]])  # type: ignore[index]
    for name in OBSERVATION_DTYPE.names or ():
        signed[name] = observations[name]
    signed["pair"][0] = -1
    with pytest.raises(stereonav.InputError, match=r"observations\[0\] pair is -1"):
        calibrate(signed, motions, rig)
    with pytest.raises(stereonav.InputError, match="huber is -1"):
        calibrate(observations, motions, rig, huber=-1.0)
    with pytest.raises(stereonav.InputError, match="observable_ratio is 2"):
        calibrate(observations, motions, rig, observable_ratio=2.0)
    with pytest.raises(stereonav.InputError, match="start camera baseline is 0"):
        calibrate(observations, motions, rig, start=dataclasses.replace(rig.nominal, baseline=0.0))
    with pytest.raises(stereonav.InputError, match=r"camera has shape \(3,\)"):
        calibrate(observations, motions, rig, start=[1.0, 2.0, 3.0])


def test_bad_rigs_are_named(tmp_path: pathlib.Path) -> None:
    observations, motions = small_data()
    with pytest.raises(stereonav.InputError, match="missing.rig.toml"):
        calibrate(observations, motions, tmp_path / "missing.rig.toml")
    rig = paper_rig()
    # A rig changed in memory is checked as a file is, when it is changed.
    with pytest.raises(stereonav.InputError, match=r"RigConfig: \[prior\] baseline: missing key"):
        rig.replace(prior={"f": 30.0})
    with pytest.raises(stereonav.InputError, match="RigConfig"):
        rig.replace(pixel_noise=float("nan"))
    with pytest.raises(stereonav.InputError, match="unknown parameter"):
        rig.replace(estimate=("f", "focus"), prior={"f": 1.0, "focus": 1.0})
    with pytest.raises(stereonav.InputTypeError, match="rig must be a stereonav.RigConfig"):
        SelfCalibrator(3)  # type: ignore[arg-type]


def test_bad_frame_and_odometry_input() -> None:
    sim, _, _ = paper_data()
    measurements = np.zeros(2, dtype=MEASUREMENT_DTYPE)
    measurements["t_us"] = sim.odometry["t_us"][5]
    measurements["id"] = 4
    measurements["uL"], measurements["uR"] = 400.0, 380.0
    with pytest.raises(stereonav.InputError, match=r"measurements\[1\] repeats landmark id 4 of measurements\[0\]"):
        frame_pairs(measurements, sim.odometry)
    measurements["vR"][1] = np.nan
    with pytest.raises(stereonav.InputError, match=r"measurements\[1\] vR is NaN"):
        frame_pairs(measurements, sim.odometry)
    unsorted = sim.odometry[::-1].copy()
    with pytest.raises(stereonav.InputError, match=r"odometry\[1\] t_us .* samples must be sorted"):
        frame_pairs(measurements[:1], unsorted)
    with pytest.raises(stereonav.InputError, match="stride is 0"):
        frame_pairs(measurements[:1], sim.odometry, stride=0)
    with pytest.raises(stereonav.InputTypeError, match="odometry has no field 'vtheta'"):
        frame_pairs(measurements[:1], sim.odometry[["t_us", "vx", "vy"]])
    first = int(sim.odometry["t_us"][0])
    with pytest.raises(stereonav.InputError, match=f"span 0: t0_us 5 is before the first odometry sample at t_us {first}"):
        integrate_odometry(sim.odometry, [5], [first])
    with pytest.raises(stereonav.InputError, match="t1_us 10 is before t0_us 20"):
        integrate_odometry(sim.odometry, [20], [10])
    with pytest.raises(stereonav.InputError, match=r"t0_us\[0\] is -1"):
        integrate_odometry(sim.odometry, [-1], [10])
    with pytest.raises(stereonav.InputTypeError, match="t0_us has dtype float64"):
        integrate_odometry(sim.odometry, [1.5], [10])


def test_bad_incremental_input() -> None:
    observations, motions = small_data()
    calibrator = SelfCalibrator(paper_rig())
    with pytest.raises(stereonav.InputError, match="motion has 2 rows"):
        calibrator.add_pair(observations[:2], motions[:2])
    bad = observations.copy()
    bad["vL0"][0] = np.nan
    with pytest.raises(stereonav.InputError, match=r"observations\[0\] vL0 is NaN"):
        calibrator.add_pairs(bad, motions)
    assert calibrator.pairs == 0, "nothing added from a bad table"
    with pytest.raises(stereonav.InputError, match="solve_every is 0"):
        SelfCalibrator(paper_rig(), solve_every=0)
    with pytest.raises(stereonav.InputError, match="consecutive is 0"):
        SelfCalibrator(paper_rig(), consecutive=0)
    with pytest.raises(stereonav.InputError, match="sigma_fraction is -1"):
        SelfCalibrator(paper_rig(), sigma_fraction=-1.0)
