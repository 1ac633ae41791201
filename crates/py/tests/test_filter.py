"""Phase 2 (the EKF) from Python: a filter stepped by hand through the paper's experiment
against the simulator's truth, the gate against a gross outlier, the state layout, copies,
the two covariance-update forms, and bad input."""

from __future__ import annotations

import copy
import dataclasses
import functools
import pathlib

import numpy as np
import pytest

import stereonav
from sim_labels import lamp_measurements
from stereonav import (
    BINDING_DTYPE,
    GATE_DTYPE,
    LANDMARK_DTYPE,
    Filter,
    FrameReport,
    Health,
    InputError,
    InputTypeError,
    UpdateReport,
)

SCENARIOS = pathlib.Path(__file__).resolve().parents[3] / "fixtures" / "scenarios"
PAPER = SCENARIOS / "paper-experiment.toml"
RIG = SCENARIOS / "paper-experiment.rig.toml"
#: The pixel noise of the rig file (1 sigma).
PIXEL_NOISE = 0.3
_FIELDS = ("uL", "vL", "uR", "vR")


def pixels(rows: np.ndarray) -> np.ndarray:
    """The ``(M, 4)`` pixels of MEASUREMENT_DTYPE rows."""
    return np.column_stack([rows[name] for name in _FIELDS]).astype(np.float64)


@dataclasses.dataclass
class Run:
    sim: stereonav.Simulation
    measurements: np.ndarray
    filter: Filter
    reports: list[FrameReport]


def step(
    f: Filter, sim: stereonav.Simulation, measurements: np.ndarray, frames: int | None = None
) -> list[FrameReport]:
    """Steps ``f`` frame by frame: odometry from the previous frame, then ``observe`` with
    the frame's lamps (lamp ids as track ids)."""
    reports = []
    previous = None
    for t_us in sim.trajectory["t_us"][:frames]:
        t_us = int(t_us)
        if previous is not None:
            f.predict_odometry(sim.odometry, previous, t_us)
        previous = t_us
        rows = measurements[measurements["t_us"] == t_us]
        reports.append(f.observe(rows["id"], pixels(rows)))
    return reports


@functools.lru_cache(maxsize=None)
def paper_data() -> tuple[stereonav.Simulation, np.ndarray]:
    sim = stereonav.simulate(PAPER)
    return sim, lamp_measurements(sim)


@functools.lru_cache(maxsize=None)
def paper_run() -> Run:
    sim, measurements = paper_data()
    f = Filter(RIG)
    return Run(sim, measurements, f, step(f, sim, measurements))


def converged() -> Filter:
    """A copy of the filter at the end of the paper's experiment (tests may change it)."""
    return paper_run().filter.copy()


def test_the_paper_experiment_maps_the_lamps_and_learns_the_baseline() -> None:
    run = paper_run()
    sim, f = run.sim, run.filter
    assert sim.trajectory[0]["x"] == sim.trajectory[0]["y"] == sim.trajectory[0]["theta"] == 0.0
    rig = stereonav.load_rig(RIG)
    assert f.estimated_parameters == ("baseline",)
    # The paper's 19-element state: the pose, five lamps, the baseline.
    assert f.state.shape == (19,) and f.state.dtype == np.float64
    # Every lamp was confirmed once, from its track (the lamp id), in three frames.
    bindings = f.bindings
    assert bindings.dtype == BINDING_DTYPE
    assert sorted(bindings["track"].tolist()) == list(range(len(sim.landmarks)))
    added = np.concatenate([r.added for r in run.reports])
    assert len(added) == 5 and set(added["track"].tolist()) == set(range(5))
    first_seen = {lamp: int(run.measurements["t_us"][run.measurements["id"] == lamp].min()) for lamp in range(5)}
    for report_index, report in enumerate(run.reports):
        for track, _ in report.added:
            frames_seen = int(np.searchsorted(sim.trajectory["t_us"], first_seen[int(track)]))
            assert report_index >= frames_seen + 2
    # Landmarks near the truth, within 4 sigma on each axis and a centimetre.
    landmarks = f.landmarks
    assert landmarks.dtype == LANDMARK_DTYPE and len(landmarks) == 5
    for track, landmark in bindings:
        row = landmarks[landmarks["id"] == landmark][0]
        error = np.array([row["x"], row["y"], row["z"]]) - sim.landmarks[track]
        sigma = np.sqrt(np.diag(row["covariance"]))
        assert np.all(np.abs(error) < 0.01), (track, error)
        assert np.all(np.abs(error) <= 4 * sigma), (track, error, sigma)
        np.testing.assert_array_equal(row["covariance"], f.landmark_covariance(int(landmark)))
    # The baseline moved from the nominal 0.12 m to within half a millimetre of the truth,
    # inside 3 sigma, and its sigma shrank far below the prior's.
    baseline, truth = f.camera.baseline, sim.camera.baseline
    sigma = float(np.sqrt(f.camera_covariance[3, 3]))
    assert abs(rig.nominal.baseline - truth) > 0.003
    assert abs(baseline - truth) < 0.0005
    assert abs(baseline - truth) <= 3 * sigma
    assert sigma < rig.prior["baseline"] / 10
    # The pose at the end of the drive (back at the start) within 2 cm and a degree.
    end = sim.trajectory[-1]
    x, y, theta = f.pose
    assert abs(x - end["x"]) < 0.02 and abs(y - end["y"]) < 0.02 and abs(theta - end["theta"]) < 0.02


def test_covariance_stays_symmetric_positive_definite_and_consistent() -> None:
    f = paper_run().filter
    p = f.covariance
    n = len(f.state)
    assert p.shape == (n, n) and p.dtype == np.float64 and p.flags.c_contiguous
    np.testing.assert_array_equal(p, p.T)
    np.linalg.cholesky(p)  # raises if not positive definite
    assert np.all(np.linalg.eigvalsh(p) > 0.0)
    np.testing.assert_array_equal(f.pose, f.state[:3])
    np.testing.assert_array_equal(f.pose_covariance, p[:3, :3])
    # The camera block is the last state; the others are zero in the 10 x 10 camera covariance.
    b = f.camera_state_index("baseline")
    assert b == n - 1 and f.state[b] == f.camera.baseline
    cc = f.camera_covariance
    assert cc.shape == (10, 10) and cc[3, 3] == p[b, b]
    assert np.count_nonzero(cc) == 1
    for k, landmark in enumerate(f.landmarks):
        i = f.landmark_state_index(int(landmark["id"]))
        assert i == 3 + 3 * k
        np.testing.assert_array_equal(f.state[i : i + 3], [landmark["x"], landmark["y"], landmark["z"]])
        np.testing.assert_array_equal(p[i : i + 3, i : i + 3], landmark["covariance"])


def test_health_counts_every_gate_outcome() -> None:
    run = paper_run()
    h = run.filter.health
    assert isinstance(h, Health)
    accepted = sum(len(r.update.accepted) for r in run.reports)
    rejected = sum(len(r.update.rejected) for r in run.reports)
    assert (h.accepted, h.rejected) == (accepted, rejected)
    assert h.landmarks_added == 5 and h.landmarks_removed == 0 and h.refused_updates == 0
    # Every frame after the five lamps' confirmation updated the filter.
    assert h.updates == sum(1 for r in run.reports if len(r.update.accepted) + len(r.update.rejected))
    assert h.updates > 900
    assert rejected <= accepted / 100
    # Each landmark's observations: the one that created it and every accepted one.
    assert int(run.filter.landmarks["observations"].sum()) == accepted + 5
    # The windowed NIS is that of a consistent filter: near 1 per dof, below its bound.
    assert h.window_observations == 100
    assert h.window_mean_nis_per_dof is not None and h.window_nis_bound is not None
    assert 0.5 < h.window_mean_nis_per_dof < h.window_nis_bound
    assert not h.nis_too_high and not h.diverged
    # Accepted NIS below the gate, rejected above it.
    nis = np.concatenate([r.update.accepted["nis"] for r in run.reports])
    assert nis.max() <= run.filter.gate_bound == pytest.approx(18.4668, abs=1e-3)
    assert 3.0 < nis.mean() < 5.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        h.accepted = 0  # type: ignore[misc]


def test_a_gross_outlier_is_rejected_and_a_false_landmark_removed() -> None:
    run = paper_run()
    f = converged()
    last = run.measurements[run.measurements["t_us"] == run.sim.trajectory["t_us"][-1]]
    assert len(last) >= 2
    landmark = int(f.bindings["landmark"][f.bindings["track"] == last["id"][0]][0])
    z = pixels(last[:1])
    bad = z + np.array([[25.0, -18.0, 25.0, -18.0]])
    before_state, before_cov = f.state, f.covariance
    report = f.update([landmark], bad)
    assert isinstance(report, UpdateReport)
    assert report.accepted.dtype == GATE_DTYPE and len(report.accepted) == 0
    assert report.rejected["id"].tolist() == [landmark]
    assert report.rejected["nis"][0] > 100 * f.gate_bound
    # A rejected observation changes nothing.
    np.testing.assert_array_equal(f.state, before_state)
    np.testing.assert_array_equal(f.covariance, before_cov)
    # The good measurement with it is accepted.
    both = f.update([landmark, int(last["id"][1])], np.vstack([bad, pixels(last[1:2])]))
    assert both.accepted["id"].tolist() == [int(last["id"][1])]
    assert both.rejected["id"].tolist() == [landmark]
    # Rejected five times in a row (max_consecutive_rejections): removed as false.
    for _ in range(2):
        assert len(f.update([landmark], bad).removed) == 0
    report = f.update([landmark], bad)
    assert report.removed.tolist() == [landmark]
    assert landmark not in f.landmarks["id"] and len(f.state) == 16
    assert f.health.landmarks_removed == 1
    with pytest.raises(InputError, match=f"landmark {landmark} is not in the map"):
        f.update([landmark], z)
    # The original is untouched by all of this.
    assert len(paper_run().filter.state) == 19


def test_observe_retires_the_track_of_a_false_landmark() -> None:
    run = paper_run()
    f = converged()
    last = run.measurements[run.measurements["t_us"] == run.sim.trajectory["t_us"][-1]]
    track = int(last["id"][0])
    bad = pixels(last[:1]) + 30.0
    removed = None
    for _ in range(5):
        report = f.observe([track], bad)
        if len(report.removed):
            removed = report.removed
    assert removed is not None and removed["track"].tolist() == [track]
    assert track not in f.bindings["track"]
    # Its measurements are ignored from now on, even good ones: it never re-enters the map.
    for _ in range(4):
        report = f.observe([track], pixels(last[:1]))
        assert report.ignored == 1 and len(report.added) == 0 and report.pending == 0


def test_predict_measurement_is_the_linearised_model() -> None:
    f = paper_run().filter
    landmark = int(f.landmarks["id"][2])
    z, s = f.predict_measurement(landmark)
    assert z.shape == (4,) and s.shape == (4, 4)
    np.testing.assert_array_equal(s, s.T)
    np.linalg.cholesky(s)
    zj, h = f.measurement_jacobian(landmark)
    np.testing.assert_array_equal(z, zj)
    n = len(f.state)
    assert h.shape == (4, n)
    # H touches the pose, this landmark and the baseline only.
    i = f.landmark_state_index(landmark)
    touched = set(np.flatnonzero(np.any(h != 0.0, axis=0)).tolist())
    assert touched <= {0, 1, 2, i, i + 1, i + 2, n - 1}
    # S is formed with the derivative but for the heading's column, which comes from the
    # observability constraint at the landmark's linearisation point.
    zp, hp = f.prediction_jacobian(landmark)
    np.testing.assert_array_equal(z, zp)
    np.testing.assert_array_equal(np.delete(hp, 2, axis=1), np.delete(h, 2, axis=1))
    np.testing.assert_allclose(s, hp @ f.covariance @ hp.T + PIXEL_NOISE**2 * np.eye(4), rtol=1e-9, atol=1e-12)
    # The model is the rig's projection of the landmark at the pose.
    landmark_row = f.landmarks[f.landmarks["id"] == landmark][0]
    point = [landmark_row["x"], landmark_row["y"], landmark_row["z"]]
    expected = stereonav.project(point, pose=f.pose, camera=f.camera).z[0]
    np.testing.assert_allclose(z, expected, rtol=1e-12)


def test_prediction_moves_the_pose_and_grows_its_covariance() -> None:
    f = Filter(RIG)
    np.testing.assert_array_equal(f.pose_covariance, np.zeros((3, 3)))
    f.predict(0.5, 0.0, 0.0, 2.0)
    np.testing.assert_allclose(f.pose, [1.0, 0.0, 0.0], atol=1e-15)
    assert np.all(np.diag(f.pose_covariance) > 0.0)
    odometry = np.zeros(3, dtype=stereonav.ODOMETRY_DTYPE)
    odometry["t_us"] = [0, 500_000, 1_000_000]
    odometry["vtheta"] = np.pi / 2
    f.predict_odometry(odometry, 0, 1_000_000)
    np.testing.assert_allclose(f.pose, [1.0, 0.0, np.pi / 2], atol=1e-12)
    # Nothing but the pose moves; the camera keeps its prior.
    assert f.state[3] == 0.12 and f.covariance[3, 3] == pytest.approx(0.006**2)


def test_the_filter_starts_from_a_handover() -> None:
    rig = stereonav.load_rig(RIG)
    b = stereonav.CAMERA_PARAMETERS.index("baseline")
    covariance = np.zeros((10, 10))
    covariance[b, b] = 0.0004**2
    observability = stereonav.Observability(params=(), max_correlation=None, eigenvalues=np.zeros(0))
    camera = dataclasses.replace(rig.nominal, baseline=0.1166)
    handover = stereonav.Handover(
        camera=camera, sigmas={}, covariance=covariance, t_us=0, observability=observability
    )
    f = Filter(rig, handover)
    assert f.camera.baseline == 0.1166 and f.state[-1] == 0.1166
    assert f.covariance[-1, -1] == pytest.approx(0.0004**2)
    # A parameter phase 1 held at nominal (variance zero) enters with the rig's prior.
    held = dataclasses.replace(handover, covariance=np.zeros((10, 10)))
    assert Filter(RIG, held).covariance[-1, -1] == pytest.approx(rig.prior["baseline"] ** 2)


def test_copies_are_independent() -> None:
    f = converged()
    g = f.copy()
    for other in (copy.copy(f), copy.deepcopy(f), g):
        assert other is not f
        np.testing.assert_array_equal(other.covariance, f.covariance)
    g.predict(0.2, 0.0, 0.1, 1.0)
    g.remove_landmark(int(g.landmarks["id"][0]))
    assert len(g.state) == len(f.state) - 3
    assert not np.array_equal(g.pose, f.pose)
    assert f.health == paper_run().filter.health
    assert "19 states, 5 landmarks" in repr(f)


def test_both_covariance_update_forms_give_the_same_filter() -> None:
    sim, measurements = paper_data()
    filters = {form: Filter(RIG, covariance_update=form) for form in ("joseph", "factored")}
    for form, f in filters.items():
        assert f.covariance_update == form
        step(f, sim, measurements, frames=200)
    joseph, factored = filters["joseph"], filters["factored"]
    np.testing.assert_allclose(factored.state, joseph.state, rtol=0, atol=1e-9)
    np.testing.assert_allclose(factored.covariance, joseph.covariance, rtol=1e-6, atol=1e-15)
    # The form can be switched on a running filter.
    f = Filter(RIG)
    assert f.covariance_update == "auto"
    f.covariance_update = "joseph"
    assert f.covariance_update == "joseph"
    with pytest.raises(InputError, match="covariance_update is 'fastest'"):
        f.covariance_update = "fastest"


def test_update_by_landmark_id() -> None:
    sim, measurements = paper_data()
    f = Filter(RIG, frames_to_confirm=1)
    first = measurements[measurements["t_us"] == sim.trajectory["t_us"][0]]
    ids = [f.add_landmark(z) for z in pixels(first)]
    assert ids == list(range(len(first)))
    assert f.landmarks["observations"].tolist() == [1] * len(first)
    assert len(f.bindings) == 0
    t0 = int(sim.trajectory["t_us"][0])
    for t_us in sim.trajectory["t_us"][1:40]:
        f.predict_odometry(sim.odometry, t0, int(t_us))
        t0 = int(t_us)
        rows = measurements[(measurements["t_us"] == t_us) & np.isin(measurements["id"], first["id"])]
        lamp_to_id = dict(zip(first["id"].tolist(), ids))
        report = f.update([lamp_to_id[int(lamp)] for lamp in rows["id"]], pixels(rows))
        assert len(report.rejected) == 0
    # An empty update is allowed and changes nothing.
    state = f.state
    report = f.update(np.zeros(0, np.uint64), np.zeros((0, 4)))
    assert len(report.accepted) == len(report.rejected) == len(report.removed) == 0
    np.testing.assert_array_equal(f.state, state)


def test_bad_input_raises_naming_the_problem() -> None:
    f = converged()
    state, covariance, health = f.state, f.covariance, f.health
    good = pixels(paper_run().measurements[:1])
    with pytest.raises(InputError, match="landmark 99 is not in the map"):
        f.update([99], good)
    with pytest.raises(InputError, match=r"z\[0\] vR \(of landmark 0\) is NaN"):
        f.update([0], np.array([[400.0, 200.0, 380.0, np.nan]]))
    with pytest.raises(InputError, match=r"z has shape \(1, 3\), expected \(1, 4\)"):
        f.update([0], good[:, :3])
    with pytest.raises(InputError, match=r"z has shape \(1, 4\), expected \(2, 4\)"):
        f.update([0, 1], good)
    with pytest.raises(InputError, match="appears twice"):
        f.update([1, 1], np.vstack([good, good]))
    with pytest.raises(InputTypeError, match="ids has dtype float64"):
        f.update(np.array([0.0]), good)
    with pytest.raises(InputError, match=r"ids\[0\] is -1"):
        f.update([-1], good)
    with pytest.raises(InputError, match=r"ids has shape \(1, 1\)"):
        f.update([[0]], good)
    with pytest.raises(InputTypeError, match="z has dtype"):
        f.update([0], [["a", "b", "c", "d"]])
    with pytest.raises(InputError, match="track 3 appears twice"):
        f.observe([3, 3], np.vstack([good, good]))
    with pytest.raises(InputError, match="time step -1 s is negative"):
        f.predict(0.1, 0.0, 0.0, -1.0)
    with pytest.raises(InputError, match="not finite"):
        f.predict(float("nan"), 0.0, 0.0, 0.1)
    with pytest.raises(InputTypeError, match="vx must be a number"):
        f.predict("fast", 0.0, 0.0, 0.1)  # type: ignore[arg-type]
    odometry = paper_run().sim.odometry
    with pytest.raises(InputError, match="before its start"):
        f.predict_odometry(odometry, 2_000_000, 1_000_000)
    with pytest.raises(InputError, match="no odometry sample at or before"):
        f.predict_odometry(odometry, 5, 1_000_000)
    with pytest.raises(InputError, match=r"odometry\[1\] t_us .* is before odometry\[0\]"):
        f.predict_odometry(odometry[::-1].copy(), 1_000_000, 1_100_000)
    with pytest.raises(InputTypeError, match="odometry must be a NumPy structured array"):
        f.predict_odometry(np.zeros((3, 4)), 0, 1)
    with pytest.raises(InputError, match="cannot be triangulated"):
        f.add_landmark([380.0, 200.0, 400.0, 200.0])  # negative disparity
    with pytest.raises(InputError, match=r"z has shape \(3,\), expected \(4,\)"):
        f.add_landmark([380.0, 200.0, 400.0])
    with pytest.raises(InputError, match="landmark 42 is not in the map"):
        f.remove_landmark(42)
    with pytest.raises(InputError, match="landmark 42 is not in the map"):
        f.landmark_state_index(42)
    with pytest.raises(InputError, match="landmark 42 is not in the map"):
        f.predict_measurement(42)
    with pytest.raises(InputError, match="landmark 42 is not in the map"):
        f.landmark_covariance(42)
    with pytest.raises(InputTypeError, match="id must be an int"):
        f.remove_landmark(True)
    with pytest.raises(InputError, match="camera parameter f is not estimated"):
        f.camera_state_index("f")
    with pytest.raises(InputError, match='"focal" is not a camera parameter'):
        f.camera_state_index("focal")
    # None of that changed anything.
    np.testing.assert_array_equal(f.state, state)
    np.testing.assert_array_equal(f.covariance, covariance)
    assert f.health == health
    # Every one of them is also a stereonav.Error and the built-in exception.
    with pytest.raises(stereonav.Error):
        f.update([99], good)
    with pytest.raises(ValueError):
        f.update([99], good)


@pytest.mark.parametrize(
    ("keywords", "error", "message"),
    [
        ({"gate_probability": 1.5}, InputError, "gate_probability is 1.5"),
        ({"gate_probability": "high"}, InputTypeError, "gate_probability must be a number"),
        ({"nis_window": 0}, InputError, "nis_window is 0"),
        ({"max_consecutive_rejections": 0}, InputError, "max_consecutive_rejections is 0"),
        ({"frames_to_confirm": 2**40}, InputError, "frames_to_confirm is 1099511627776"),
        ({"consistency_probability": 0.0}, InputError, "consistency_probability is 0.0"),
        ({"covariance_update": "fast"}, InputError, "covariance_update is 'fast'"),
        ({"covariance_update": 1}, InputTypeError, "covariance_update must be a str"),
        ({"handover": "calibrated"}, InputTypeError, "handover must be a stereonav.Handover"),
    ],
)
def test_bad_settings_raise(keywords: dict[str, object], error: type, message: str) -> None:
    with pytest.raises(error, match=message):
        Filter(RIG, **keywords)  # type: ignore[arg-type]


def test_bad_rigs_raise(tmp_path: pathlib.Path) -> None:
    with pytest.raises(InputTypeError, match="rig must be a stereonav.RigConfig"):
        Filter(3)  # type: ignore[arg-type]
    with pytest.raises(InputError, match="no-such.rig.toml"):
        Filter(tmp_path / "no-such.rig.toml")
    with pytest.raises(InputError, match=r"RigConfig: \[prior\] (baseline|f): missing key"):
        stereonav.load_rig(RIG).replace(prior={})
