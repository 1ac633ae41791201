"""The whole stack from Python: ``stereonav.replay`` on the committed paper logs (the summary
shaped as ``SUMMARY.json`` of vehicle-interfaces.md section 5, the arrays, the written outputs
read back by third-party readers), bad input named in the exception, and ``stereonav.Navigator``
fed by hand from the simulator, equal to the replay of the same data."""

from __future__ import annotations

import csv
import functools
import json
import math
import pathlib
import re
from typing import Any

import numpy as np
import pytest

import stereonav
from stereonav import (
    CAMERA_PARAMETERS,
    FRAME_INFO_DTYPE,
    GATE_DTYPE,
    MAP_LANDMARK_DTYPE,
    NIS_DTYPE,
    PHASES,
    TRAJECTORY_DTYPE,
    FrameOutcome,
    InputError,
    InputTypeError,
    Navigator,
    ParamEstimate,
    Replay,
    replay,
)

ROOT = pathlib.Path(__file__).resolve().parents[3]
LOGS = ROOT / "fixtures" / "logs"
SCENARIOS = ROOT / "fixtures" / "scenarios"
EXPERIMENT_LOG = LOGS / "paper-experiment.mcap"
EXPERIMENT_RIG = LOGS / "paper-experiment.rig.toml"
CALIBRATION_LOG = LOGS / "paper-calibration.mcap"
SHARED = ROOT.parent / "shared" / "data"
#: MCAP files written by other tools (ROS 2), in the shared data folder when it exists.
FOREIGN = SHARED / "foreign-mcap"
#: Foxglove's JSON Schemas of its well-known message types, by name (``PoseInFrame.json``).
FOXGLOVE_SCHEMAS = SHARED / "foxglove-jsonschema"
#: The lamps of the paper's scenarios.
LAMPS = 5
#: The topics of EST.mcap and their schemas (crates/estimates-log/src/topics.rs).
EST_TOPICS = {
    "/est/pose": "foxglove.PoseInFrame",
    "/est/trajectory": "foxglove.PosesInFrame",
    "/est/landmarks": "foxglove.SceneUpdate",
    "/est/camera": "stereonav.CameraEstimate",
    "/est/frame": "stereonav.FrameInfo",
    "/est/summary": "stereonav.Summary",
}


@functools.lru_cache(maxsize=None)
def experiment() -> Replay:
    """The paper's experiment from the rig's priors (phase 1 skipped), once per session."""
    return replay(EXPERIMENT_LOG, EXPERIMENT_RIG, skip_phase1=True)


@functools.lru_cache(maxsize=None)
def calibration() -> Replay:
    """The paper's calibration drive with both phases, the rig from the log."""
    return replay(CALIBRATION_LOG)


@pytest.fixture(scope="module")
def outputs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, pathlib.Path]:
    """The experiment's three outputs, written once per module."""
    directory = tmp_path_factory.mktemp("replay-outputs")
    r = experiment()
    paths = {
        "est": directory / "EST.mcap",
        "summary": directory / "SUMMARY.json",
        "trajectory": directory / "TRAJ.csv",
    }
    r.write_estimates(paths["est"])
    r.write_summary(str(paths["summary"]))
    r.write_trajectory(paths["trajectory"])
    return paths


def is_int(value: object) -> bool:
    return type(value) is int


def is_float(value: object) -> bool:
    return type(value) is float


# --- The replay ----------------------------------------------------------------------------


def test_the_summary_has_the_keys_and_types_of_section_5() -> None:
    summary = experiment().summary
    assert {"frames", "corrupt", "lost", "phase_switch_t_us", "pose", "camera", "landmarks"} <= set(summary)
    for key in ("frames", "corrupt", "lost"):
        assert is_int(summary[key]), (key, summary[key])
    assert summary["frames"] == 961 and summary["corrupt"] == summary["lost"] == 0
    # Phase 1 was skipped: no switch.
    assert summary["phase_switch_t_us"] is None and summary["phase1_skipped"] is True
    pose = summary["pose"]
    assert set(pose) == {"t_us", "x", "y", "theta"}
    assert is_int(pose["t_us"]) and all(is_float(pose[k]) for k in ("x", "y", "theta"))
    camera = summary["camera"]
    assert set(camera) == set(CAMERA_PARAMETERS)
    for name, estimate in camera.items():
        assert set(estimate) == {"value", "sigma"}, name
        assert is_float(estimate["value"]) and is_float(estimate["sigma"]), (name, estimate)
    landmarks = summary["landmarks"]
    assert isinstance(landmarks, list) and len(landmarks) == LAMPS
    for landmark in landmarks:
        assert set(landmark) == {"id", "x", "y", "z", "sigma", "observations"}
        assert is_int(landmark["id"]) and is_int(landmark["observations"])
        assert all(is_float(landmark[k]) for k in ("x", "y", "z"))
        assert isinstance(landmark["sigma"], list) and len(landmark["sigma"]) == 3
        assert all(is_float(s) and s > 0 for s in landmark["sigma"])
    # The rest of the summary, and a new dict at each access.
    assert summary["warnings"] == [] and isinstance(summary["counts"], dict)
    summary["frames"] = -1
    assert experiment().summary["frames"] == 961


def test_the_experiment_maps_the_lamps_and_learns_the_baseline() -> None:
    r = experiment()
    truth = r.truth
    assert truth is not None and truth == r.summary["truth"]
    # The baseline from the rig's 0.12 m to within half a millimetre of the truth (its error
    # is summary["truth"]["camera"]["baseline"]), inside 3 sigma.
    error = truth["camera"]["baseline"]
    assert abs(error) < 0.0005, error
    assert abs(error) <= 3 * r.camera["baseline"].sigma
    assert r.camera["baseline"] == ParamEstimate(**r.summary["camera"]["baseline"])
    assert truth["landmarks_matched"] == LAMPS and truth["landmarks_unmatched"] == 0
    assert truth["lamps_missed"] == 0 and truth["landmark_rms_m"] < 0.005
    # The filter's NEES against the truth: pose (3 dof) and full state (pose, 5 landmarks, B).
    consistency = truth["consistency"]
    assert consistency["state_dof"] == 3 + 3 * LAMPS + 1
    # Every frame but the first, whose pose is the world origin exactly (zero covariance).
    assert consistency["pose_frames"] == len(r.trajectory) - 1
    assert 0 < consistency["pose_nees"] < 3 * 3 and 0 < consistency["state_nees"] < 3 * 19
    assert r.warnings == () and r.phase_switch_t_us is None and r.phase1_skipped


def test_the_arrays_match_the_summary() -> None:
    r = experiment()
    summary = r.summary
    trajectory = r.trajectory
    assert trajectory.dtype == TRAJECTORY_DTYPE
    assert trajectory.dtype == np.dtype([("t_us", "<u8"), ("x", "<f8"), ("y", "<f8"), ("theta", "<f8")])
    assert len(trajectory) == summary["frames"] == r.counts["frames"]
    assert np.all(np.diff(trajectory["t_us"].astype(np.int64)) > 0)
    last = trajectory[-1]
    assert summary["pose"] == {"t_us": int(last["t_us"]), "x": last["x"], "y": last["y"], "theta": last["theta"]}
    assert r.pose_covariance.shape == (len(trajectory), 3, 3)
    # Every frame in phase 2 (phase 1 skipped).
    assert r.phase.dtype == np.uint8 and r.phase.shape == (len(trajectory),)
    assert PHASES == ("calibrating", "navigating") and set(r.phase.tolist()) == {1}
    frames = r.frames
    assert frames.dtype == FRAME_INFO_DTYPE
    np.testing.assert_array_equal(frames["t_us"], trajectory["t_us"])
    assert frames["landmarks"][-1] == LAMPS
    # One NIS row per accepted observation, each landmark in the map.
    nis = r.nis
    assert nis.dtype == NIS_DTYPE and len(nis) == int(frames["accepted"].sum()) > 0
    assert set(nis["id"].tolist()) == set(r.landmarks["id"].tolist())
    assert np.all(np.isfinite(nis["nis"])) and np.all(nis["nis"] >= 0)
    assert 2.0 < float(nis["nis"].mean()) < 6.0  # chi-square, 4 dof: mean 4
    # The map, as the summary's landmarks.
    landmarks = r.landmarks
    assert landmarks.dtype == MAP_LANDMARK_DTYPE and len(landmarks) == LAMPS
    for row, entry in zip(landmarks, summary["landmarks"]):
        assert int(row["id"]) == entry["id"] and int(row["observations"]) == entry["observations"]
        assert [row["x"], row["y"], row["z"]] == [entry["x"], entry["y"], entry["z"]]
        assert [row["sx"], row["sy"], row["sz"]] == entry["sigma"]
        np.testing.assert_array_equal(np.sqrt(np.diag(row["covariance"])), entry["sigma"])
    assert r.maps and r.maps[-1].t_us == int(trajectory["t_us"][-1])
    np.testing.assert_array_equal(r.maps[-1].landmarks, landmarks)
    # The camera over time: one sample per phase-2 frame, the last one the final estimate.
    history = r.camera_history
    assert history.values.shape == history.sigmas.shape == (len(trajectory), len(CAMERA_PARAMETERS))
    np.testing.assert_array_equal(history.t_us, trajectory["t_us"])
    b = CAMERA_PARAMETERS.index("baseline")
    assert history.values[-1, b] == r.camera["baseline"].value
    assert history.sigmas[0, b] > 10 * history.sigmas[-1, b]
    assert set(r.camera) == set(CAMERA_PARAMETERS)
    # Read-only results.
    with pytest.raises(ValueError):
        trajectory["x"][0] = 1.0
    with pytest.raises(ValueError):
        landmarks["x"][0] = 1.0
    assert "961 frames" in repr(r) and "5 landmarks" in repr(r)


def test_the_calibration_drive_switches_to_phase_2() -> None:
    r = calibration()
    assert not r.phase1_skipped and r.warnings == ()
    switch = r.phase_switch_t_us
    assert isinstance(switch, int) and r.summary["phase_switch_t_us"] == switch
    # Phase 1 up to the switch, phase 2 from the frame of the switch on.
    t_us = r.trajectory["t_us"]
    np.testing.assert_array_equal(r.phase, (t_us >= switch).astype(np.uint8))
    assert 0 < int(np.count_nonzero(r.phase == 0)) < len(t_us)
    # The camera over time: phase 1's solves, then every phase-2 frame.
    history = r.camera_history
    assert history.phase[0] == 0 and history.phase[-1] == 1
    assert np.all(np.diff(history.phase.astype(np.int8)) >= 0)
    assert r.counts["phase1_solves"] > 0 and len(r.landmarks) == LAMPS
    # Phase 1's hand-over (the first phase-2 row of the camera history) holds the baseline
    # within 1 mm; phase 2 then drifts on this drive (docs/phase2.md, issue 15 item 4).
    b = stereonav.CAMERA_PARAMETERS.index("baseline")
    first = int(np.argmax(history.phase == 1))
    assert abs(history.values[first, b] - 0.1164) < 0.001


def test_summary_json_and_traj_csv_read_back(outputs: dict[str, pathlib.Path]) -> None:
    r = experiment()
    assert json.loads(outputs["summary"].read_text()) == r.summary
    with outputs["trajectory"].open(newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["t_us", "x", "y", "theta"]
    assert len(rows) == 1 + len(r.trajectory)
    for row, pose in zip(rows[1:], r.trajectory):
        assert int(row[0]) == int(pose["t_us"])
        assert [float(v) for v in row[1:]] == [pose["x"], pose["y"], pose["theta"]]


def est_messages(path: pathlib.Path) -> list[tuple[Any, Any, Any]]:
    """Every (schema, channel, message) of an MCAP file, CRCs checked."""
    mcap_reader = pytest.importorskip("mcap.reader")
    with path.open("rb") as f:
        reader = mcap_reader.make_reader(f, validate_crcs=True)
        assert reader.get_summary() is not None
        return list(reader.iter_messages(log_time_order=False))


def test_est_mcap_reads_with_crc_validation(outputs: dict[str, pathlib.Path]) -> None:
    r = experiment()
    messages = est_messages(outputs["est"])
    counts: dict[str, int] = {}
    for schema, channel, message in messages:
        assert EST_TOPICS[channel.topic] == schema.name, channel.topic
        assert channel.message_encoding == "json" and schema.encoding == "jsonschema"
        json.loads(schema.data)
        data = json.loads(message.data)  # every message is JSON
        assert isinstance(data, dict)
        counts[channel.topic] = counts.get(channel.topic, 0) + 1
        if channel.topic == "/est/summary":
            assert data == r.summary
    assert set(counts) == set(EST_TOPICS)
    assert counts["/est/pose"] == counts["/est/frame"] == len(r.trajectory)
    assert counts["/est/summary"] == 1 and counts["/est/landmarks"] == len(r.maps)


def missing_properties(schema: dict[str, Any], value: object, where: str) -> list[str]:
    """Where ``value`` lacks a property its schema lists, recursively into the objects and
    arrays of objects present (Foxglove's schemas have no ``required``)."""
    missing = []
    if isinstance(value, dict):
        for name, sub in schema.get("properties", {}).items():
            if name not in value:
                missing.append(f"{where}.{name}")
            else:
                missing += missing_properties(sub, value[name], f"{where}.{name}")
    elif isinstance(value, list) and isinstance(schema.get("items"), dict):
        for i, item in enumerate(value):
            missing += missing_properties(schema["items"], item, f"{where}[{i}]")
    return missing


@pytest.mark.skipif(
    not FOXGLOVE_SCHEMAS.is_dir(), reason=f"no Foxglove JSON Schemas in {FOXGLOVE_SCHEMAS}"
)
def test_est_mcap_messages_validate_against_foxglove_schemas(outputs: dict[str, pathlib.Path]) -> None:
    jsonschema = pytest.importorskip("jsonschema")
    validators: dict[str, Any] = {}
    checked: dict[str, int] = {}
    for schema, channel, message in est_messages(outputs["est"]):
        data = json.loads(message.data)
        # Every message against the schema written with it in the file.
        embedded = json.loads(schema.data)
        key = f"embedded {schema.name}"
        if key not in validators:
            cls = jsonschema.validators.validator_for(embedded)
            cls.check_schema(embedded)
            validators[key] = cls(embedded)
        validators[key].validate(data)
        if not schema.name.startswith("foxglove."):
            continue
        # Foxglove's messages against Foxglove's own schemas, every property present.
        name = schema.name.removeprefix("foxglove.")
        if name not in validators:
            foxglove = json.loads((FOXGLOVE_SCHEMAS / f"{name}.json").read_text())
            cls = jsonschema.validators.validator_for(foxglove)
            validators[name] = cls(foxglove)
            validators[f"raw {name}"] = foxglove
        validators[name].validate(data)
        assert missing_properties(validators[f"raw {name}"], data, channel.topic) == []
        checked[name] = checked.get(name, 0) + 1
    assert set(checked) == {"PoseInFrame", "PosesInFrame", "SceneUpdate"}, checked


# --- Bad input -----------------------------------------------------------------------------


def test_a_missing_log_names_the_path(tmp_path: pathlib.Path) -> None:
    missing = tmp_path / "no-such-log.mcap"
    with pytest.raises(InputError, match=re.escape(str(missing))) as info:
        replay(missing, EXPERIMENT_RIG)
    assert isinstance(info.value, stereonav.Error) and isinstance(info.value, ValueError)
    assert isinstance(info.value.__cause__, FileNotFoundError)
    assert "\n" not in str(info.value)


def test_files_that_are_not_vehicle_logs_are_named(tmp_path: pathlib.Path) -> None:
    with pytest.raises(InputError, match=re.escape(f"{EXPERIMENT_RIG} is not an MCAP file")):
        replay(EXPERIMENT_RIG)
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    with pytest.raises(InputError, match="empty.mcap is not an MCAP file: it is empty"):
        replay(empty)


@pytest.mark.skipif(
    not FOREIGN.is_dir() or not any(FOREIGN.glob("*.mcap")),
    reason=f"no foreign MCAP files in {FOREIGN}",
)
def test_a_foreign_mcap_file_is_not_a_vehicle_log() -> None:
    for path in sorted(FOREIGN.glob("*.mcap")):
        with pytest.raises(InputError, match=re.escape(f"{path} is not a vehicle log")) as info:
            replay(path, EXPERIMENT_RIG)
        assert "\n" not in str(info.value)


def edited_rig(tmp_path: pathlib.Path, name: str, old: str, new: str) -> pathlib.Path:
    text = EXPERIMENT_RIG.read_text()
    assert old in text
    path = tmp_path / name
    path.write_text(text.replace(old, new))
    return path


def test_bad_rig_files_name_the_file_and_key(tmp_path: pathlib.Path) -> None:
    missing = edited_rig(tmp_path, "no-baseline.rig.toml", "baseline = 0.12\n", "")
    with pytest.raises(InputError, match=r"no-baseline.rig.toml: \[camera\] baseline: missing key"):
        replay(EXPERIMENT_LOG, missing)
    wrong = edited_rig(tmp_path, "wide.rig.toml", "baseline = 0.12\n", 'baseline = "wide"\n')
    with pytest.raises(InputError, match=r"wide.rig.toml: \[camera\] baseline: expected a number"):
        replay(EXPERIMENT_LOG, wrong)
    unknown = edited_rig(
        tmp_path, "focal.rig.toml", 'parameters = ["baseline"]', 'parameters = ["baseline", "focal"]'
    )
    with pytest.raises(InputError, match=r'focal.rig.toml: \[estimate\] parameters: unknown parameter "focal"'):
        replay(EXPERIMENT_LOG, unknown)
    with pytest.raises(InputError, match="no-such.rig.toml"):
        replay(EXPERIMENT_LOG, tmp_path / "no-such.rig.toml")


def test_bad_arguments_are_named() -> None:
    with pytest.raises(InputTypeError, match="log_path must be"):
        replay(42)  # type: ignore[arg-type]
    with pytest.raises(InputTypeError, match="rig_path must be a stereonav.RigConfig"):
        replay(EXPERIMENT_LOG, 3.0)  # type: ignore[arg-type]
    with pytest.raises(InputTypeError, match="skip_phase1 must be a bool"):
        replay(EXPERIMENT_LOG, skip_phase1="yes")  # type: ignore[arg-type]
    with pytest.raises(InputTypeError, match="phase1_frames must be an int"):
        replay(EXPERIMENT_LOG, phase1_frames=2.5)  # type: ignore[arg-type]
    with pytest.raises(InputError, match="phase1_frames is 1"):
        replay(EXPERIMENT_LOG, phase1_frames=1)
    with pytest.raises(TypeError):
        replay(EXPERIMENT_LOG, EXPERIMENT_RIG, True)  # type: ignore[misc]


def test_a_truncated_log_replays_as_far_as_it_goes_with_a_warning(tmp_path: pathlib.Path) -> None:
    data = EXPERIMENT_LOG.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    r = replay(cut, skip_phase1=True)
    assert any("ends early" in w for w in r.warnings), r.warnings
    assert r.summary["warnings"] == list(r.warnings)
    assert 0 < len(r.trajectory) < len(experiment().trajectory)
    assert len(r.trajectory) == r.summary["frames"]


def test_unwritable_outputs_name_the_path(tmp_path: pathlib.Path) -> None:
    r = experiment()
    missing = tmp_path / "no-such-dir" / "EST.mcap"
    for write in (r.write_estimates, r.write_summary, r.write_trajectory):
        with pytest.raises(InputError, match=re.escape(str(missing))) as info:
            write(missing)
        assert isinstance(info.value.__cause__, FileNotFoundError)
    with pytest.raises(InputTypeError, match="path must be"):
        r.write_summary(3)  # type: ignore[arg-type]


# --- The navigator fed by hand -------------------------------------------------------------


@functools.lru_cache(maxsize=None)
def simulated(scenario: str) -> tuple[stereonav.Simulation, tuple[stereonav.Frame, ...]]:
    """A scenario simulated, with its board frames decoded and sorted by time (the order in
    which the vehicle must feed them; the replay sorts the same way)."""
    sim = stereonav.simulate(SCENARIOS / f"{scenario}.toml")
    decoder = stereonav.StreamDecoder()
    frames = decoder.push(sim.stream) + decoder.finish()
    return sim, tuple(sorted(frames, key=lambda f: f.t_us))


def drive(
    nav: Navigator, scenario: str, frames: int | None = None, pixels: bool = False
) -> list[FrameOutcome]:
    """Feeds ``nav`` with the scenario: the odometry up to each frame's time, then the frame
    (as the decoder's Q12.4 records, or as float pixels when ``pixels``)."""
    sim, decoded = simulated(scenario)
    odometry = sim.odometry
    outcomes = []
    start = 0
    for frame in decoded[:frames]:
        end = int(np.searchsorted(odometry["t_us"], frame.t_us, side="right"))
        nav.push_odometry_samples(odometry[start:end])
        start = end
        if pixels:
            left = np.column_stack([frame.left["x_q4"], frame.left["y_q4"]]) / 16.0
            right = np.column_stack([frame.right["x_q4"], frame.right["y_q4"]]) / 16.0
            outcomes.append(nav.push_frame(frame.t_us, left, right))
        else:
            outcomes.append(nav.push_frame(frame.t_us, frame.left, frame.right))
    return outcomes


@functools.lru_cache(maxsize=None)
def experiment_navigator() -> tuple[Navigator, tuple[FrameOutcome, ...]]:
    nav = Navigator(SCENARIOS / "paper-experiment.rig.toml", skip_phase1=True)
    outcomes = tuple(drive(nav, "paper-experiment"))
    # The end of the drive, as replay does: phase 2's smoother solves over its last frames.
    assert nav.finish() is False
    return nav, outcomes


def test_the_navigator_maps_the_experiments_lamps_from_the_priors() -> None:
    nav, outcomes = experiment_navigator()
    sim, _ = simulated("paper-experiment")
    assert nav.phase == "navigating" and nav.phase_switch_t_us is None
    assert not any(o.switched or o.solved for o in outcomes)
    assert nav.stats["frames"] == len(sim.trajectory) and nav.stats["refused_updates"] == 0
    assert nav.stats["odometry"] == int(np.count_nonzero(sim.odometry["t_us"] <= sim.trajectory["t_us"][-1]))
    assert nav.last_frame_t_us == int(sim.trajectory["t_us"][-1])
    # Five landmarks, each added once, each within a centimetre of its lamp.
    added = np.concatenate([o.added for o in outcomes])
    assert sorted(added.tolist()) == list(range(LAMPS))
    landmarks = nav.landmarks
    assert landmarks.dtype == MAP_LANDMARK_DTYPE and landmarks["id"].tolist() == list(range(LAMPS))
    for row in landmarks:
        distances = np.linalg.norm(sim.landmarks - [row["x"], row["y"], row["z"]], axis=1)
        assert distances.min() < 0.01, (row["id"], distances.min())
    # The outcomes: accepted observations with their NIS, of landmarks in the map.
    accepted = np.concatenate([o.accepted for o in outcomes])
    assert accepted.dtype == GATE_DTYPE and len(accepted) > 10 * len(outcomes) // 4
    assert set(accepted["id"].tolist()) <= set(landmarks["id"].tolist())
    assert all(o.rematched.dtype == stereonav.BINDING_DTYPE for o in outcomes)
    # The baseline learnt, the pose back at the start.
    baseline = nav.camera["baseline"]
    assert abs(baseline.value - sim.camera.baseline) < 0.0005
    assert set(nav.camera) == set(CAMERA_PARAMETERS)
    assert nav.camera["f"] == ParamEstimate(700.0, 0.0)
    end = sim.trajectory[-1]
    np.testing.assert_allclose(nav.pose, [end["x"], end["y"], end["theta"]], atol=0.02)
    p = nav.pose_covariance
    assert p.shape == (3, 3) and np.all(np.linalg.eigvalsh(p) > 0)
    assert nav.camera_covariance.shape == (10, 10)
    assert "navigating, 5 landmarks" in repr(nav)


def test_the_navigator_by_hand_equals_the_replay_of_the_log() -> None:
    """The log is the same simulation (fixtures/README.md): the same numbers, bit for bit."""
    nav, _ = experiment_navigator()
    r = replay(EXPERIMENT_LOG, skip_phase1=True)
    last = r.trajectory[-1]
    np.testing.assert_array_equal(nav.pose, [last["x"], last["y"], last["theta"]])
    np.testing.assert_array_equal(nav.pose_covariance, r.pose_covariance[-1])
    np.testing.assert_array_equal(nav.landmarks, r.landmarks)
    assert nav.camera == r.camera


def test_pixels_and_board_records_give_the_same_frames() -> None:
    rig = SCENARIOS / "paper-experiment.rig.toml"
    q4, px = Navigator(rig, skip_phase1=True), Navigator(rig, skip_phase1=True)
    drive(q4, "paper-experiment", frames=200)
    drive(px, "paper-experiment", frames=200, pixels=True)
    np.testing.assert_array_equal(q4.landmarks, px.landmarks)
    np.testing.assert_array_equal(q4.pose, px.pose)


def test_the_navigator_switches_to_phase_2_on_the_calibration_drive() -> None:
    nav = Navigator(SCENARIOS / "paper-calibration.rig.toml")
    assert nav.phase == "calibrating" and len(nav.landmarks) == 0
    outcomes = drive(nav, "paper-calibration")
    assert nav.phase == "navigating"
    switched = [o for o in outcomes if o.switched]
    assert len(switched) == 1 and switched[0].solved
    assert nav.phase_switch_t_us == calibration().phase_switch_t_us
    assert nav.stats["phase1_solves"] == calibration().counts["phase1_solves"]
    assert len(nav.landmarks) == LAMPS


def test_finish_hands_phase_1_over_at_the_end_of_a_short_drive() -> None:
    """Ten seconds of the calibration drive: not stable yet, so finish() hands over and the
    lamps seen so far are mapped (never an empty map); a second finish() changes nothing."""
    nav = Navigator(SCENARIOS / "paper-calibration.rig.toml")
    drive(nav, "paper-calibration", frames=200)
    assert nav.phase == "calibrating" and len(nav.landmarks) == 0
    assert nav.finish() is True
    assert nav.phase == "navigating" and nav.phase_switch_t_us == nav.last_frame_t_us
    assert len(nav.landmarks) > 0
    landmarks = nav.landmarks.copy()
    assert nav.finish() is False
    np.testing.assert_array_equal(nav.landmarks, landmarks)


def test_odometry_given_as_scalars_or_arrays() -> None:
    nav = Navigator(EXPERIMENT_RIG)
    nav.push_odometry(0, 0.5, 0.0, 0.0)
    nav.push_odometry(np.array([500_000, 1_000_000]), [0.5, 0.5], 0.0, [0.0, 0.0])
    nav.push_odometry([], [], [], [])
    outcome = nav.push_frame(0, np.zeros((0, 2)), [])
    assert outcome.no_odometry is False and len(outcome.accepted) == 0
    assert nav.push_frame(1_000_000, [], []).no_odometry is False
    # Dead reckoning in phase 1: 0.5 m/s for one second.
    np.testing.assert_allclose(nav.pose, [0.5, 0.0, 0.0], atol=1e-12)
    assert nav.pose_covariance[0, 0] > 0
    assert nav.stats["odometry"] == 3 and nav.stats["frames"] == 2
    # Before the first solve, the camera is the rig's nominal one with its prior sigmas.
    assert nav.camera["baseline"] == ParamEstimate(0.12, 0.006)


def test_nan_and_out_of_order_inputs_raise_and_change_nothing() -> None:
    nav = Navigator(EXPERIMENT_RIG, skip_phase1=True)
    nav.push_odometry([0, 10_000], [0.1, 0.1], [0.0, 0.0], [0.0, 0.0])
    nav.push_frame(10_000, [[400.0, 240.0]], [[380.0, 240.0]])
    before = (nav.stats, nav.pose.copy(), nav.pose_covariance.copy(), nav.last_frame_t_us)
    with pytest.raises(InputError, match=r"odometry\[0\] vx is NaN, not a finite number"):
        nav.push_odometry(20_000, float("nan"), 0.0, 0.0)
    with pytest.raises(InputError, match=r"odometry\[1\] vtheta is inf"):
        nav.push_odometry([20_000, 30_000], 0.1, 0.0, [0.0, float("inf")])  # type: ignore[arg-type]
    with pytest.raises(InputError, match=r"odometry\[0\] t_us 5000 is before the last sample pushed \(t_us 10000\)"):
        nav.push_odometry(5_000, 0.1, 0.0, 0.0)
    with pytest.raises(InputError, match=r"odometry\[1\] t_us 20000 is before odometry\[0\] t_us 30000"):
        nav.push_odometry([30_000, 20_000], [0.1, 0.1], [0.0, 0.0], [0.0, 0.0])
    with pytest.raises(InputError, match=r"vy has shape \(3,\), expected \(2,\)"):
        nav.push_odometry([20_000, 30_000], [0.1, 0.1], [0.0, 0.0, 0.0], [0.0, 0.0])
    with pytest.raises(InputError, match=r"t_us\[0\] is -1"):
        nav.push_odometry(-1, 0.1, 0.0, 0.0)
    with pytest.raises(InputTypeError, match="t_us has dtype float64"):
        nav.push_odometry(2.5e4, 0.1, 0.0, 0.0)
    with pytest.raises(InputTypeError, match="vx must be numbers"):
        nav.push_odometry(20_000, "fast", 0.0, 0.0)  # type: ignore[arg-type]
    with pytest.raises(InputError, match=r"left\[1\] u is NaN, not a finite number"):
        nav.push_frame(20_000, [[400.0, 240.0], [np.nan, 240.0]], [[380.0, 240.0]])
    with pytest.raises(InputError, match=r"right\[0\] v is inf"):
        nav.push_frame(20_000, [[400.0, 240.0]], [[380.0, np.inf]])
    with pytest.raises(InputError, match=r"stereo frame at t = 5000 us is older than the previous one \(10000 us\)"):
        nav.push_frame(5_000, [[400.0, 240.0]], [[380.0, 240.0]])
    with pytest.raises(InputError, match=r"left has shape \(1, 3\), expected \(N, 2\)"):
        nav.push_frame(20_000, [[400.0, 240.0, 1.0]], [])
    with pytest.raises(InputTypeError, match="right has dtype <U1"):
        nav.push_frame(20_000, [], [["a", "b"]])
    with pytest.raises(InputTypeError, match="expected the fields x_q4 and y_q4"):
        nav.push_frame(20_000, np.zeros(2, dtype=[("u", "<f8"), ("v", "<f8")]), [])
    with pytest.raises(InputError, match=r"left\[0\] x_q4 is -1"):
        nav.push_frame(20_000, np.array([(-1, 5)], dtype=[("x_q4", "<i4"), ("y_q4", "<i4")]), [])
    with pytest.raises(InputTypeError, match="t_us must be an int"):
        nav.push_frame(2.0e4, [], [])  # type: ignore[arg-type]
    with pytest.raises(InputError, match="t_us is -5"):
        nav.push_frame(-5, [], [])
    with pytest.raises(InputTypeError, match="odometry must be a NumPy structured array"):
        nav.push_odometry_samples(np.zeros((3, 4)))
    # Nothing changed, and each is also a stereonav.Error and the built-in exception.
    assert (nav.stats, nav.last_frame_t_us) == (before[0], before[3])
    np.testing.assert_array_equal(nav.pose, before[1])
    np.testing.assert_array_equal(nav.pose_covariance, before[2])
    with pytest.raises(stereonav.Error):
        nav.push_frame(5_000, [], [])
    with pytest.raises(ValueError):
        nav.push_frame(5_000, [], [])


def test_bad_navigator_settings_raise(tmp_path: pathlib.Path) -> None:
    with pytest.raises(InputTypeError, match="rig must be a stereonav.RigConfig"):
        Navigator(3)  # type: ignore[arg-type]
    with pytest.raises(InputError, match="no-such.rig.toml"):
        Navigator(tmp_path / "no-such.rig.toml")
    with pytest.raises(InputTypeError, match="skip_phase1 must be a bool"):
        Navigator(EXPERIMENT_RIG, skip_phase1=1)  # type: ignore[arg-type]
    with pytest.raises(InputError, match="phase1_frames is 1"):
        Navigator(EXPERIMENT_RIG, phase1_frames=1)
    rig = stereonav.load_rig(EXPERIMENT_RIG)
    assert Navigator(rig, phase1_frames=200).phase == "calibrating"
    with pytest.raises(InputError, match=r"RigConfig: \[prior\] (baseline|f): missing key"):
        Navigator(rig.replace(prior={}))
    assert math.isfinite(Navigator(rig).camera["baseline"].value)


def test_the_camera_considered_in_phase_2_keeps_phase_1s_estimate() -> None:
    refined = replay(LOGS / "paper-calibration.mcap")
    considered = replay(LOGS / "paper-calibration.mcap", consider_camera=True)
    switch = considered.phase_switch_t_us
    assert switch is not None and switch == refined.phase_switch_t_us
    history = considered.camera_history
    first = int(np.argmax(history.t_us == switch))
    # Phase 2 from the switch on: the camera parameters do not move.
    assert np.array_equal(history.values[first:], np.broadcast_to(history.values[first], history.values[first:].shape))
    assert considered.summary["camera"] != refined.summary["camera"]
    with pytest.raises(InputTypeError):
        replay(LOGS / "paper-calibration.mcap", consider_camera="yes")  # type: ignore[arg-type]
    nav = Navigator(LOGS / "paper-calibration.rig.toml", consider_camera=True)
    assert nav.phase == "calibrating"
