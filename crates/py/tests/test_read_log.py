"""Vehicle logs read whole from Python (``stereonav.read_log``): the committed paper-experiment
log as logged (stream, frames, odometry, rig, truth), a simulated run read back equal to the
simulation, a log cut short, and files that are not vehicle logs named in the exception."""

from __future__ import annotations

import functools
import json
import pathlib
import re

import numpy as np
import pytest

import stereonav
from stereonav import (
    ODOMETRY_DTYPE,
    TRAJECTORY_DTYPE,
    Camera,
    Frame,
    InputError,
    InputTypeError,
    LogTruth,
    StreamDecoder,
    StreamStats,
    VehicleLog,
    load_rig,
    read_log,
)

ROOT = pathlib.Path(__file__).resolve().parents[3]
LOGS = ROOT / "fixtures" / "logs"
SCENARIOS = ROOT / "fixtures" / "scenarios"
EXPERIMENT_LOG = LOGS / "paper-experiment.mcap"
EXPERIMENT_RIG = LOGS / "paper-experiment.rig.toml"
#: An MCAP file written by another tool (ROS 2), in the shared data folder when it exists.
FOREIGN_LOG = ROOT.parent / "shared" / "data" / "foreign-mcap" / "nav2_turtlebot.mcap"
#: Good packets in the paper-experiment log.
EXPERIMENT_FRAMES = 961
#: The lamps of the paper's scenarios.
LAMPS = 5


@functools.lru_cache(maxsize=None)
def experiment() -> VehicleLog:
    return read_log(EXPERIMENT_LOG)


def test_the_experiment_log_decodes_to_its_frames() -> None:
    log = experiment()
    assert isinstance(log, VehicleLog)
    assert log.path == str(EXPERIMENT_LOG)
    assert isinstance(log.stream, bytes) and 0 < log.chunks <= len(log.stream)
    assert len(log.frames) == EXPERIMENT_FRAMES
    assert all(isinstance(f, Frame) for f in log.frames)
    assert isinstance(log.stream_stats, StreamStats)
    assert log.stream_stats.packets == EXPERIMENT_FRAMES
    # The frames are the stream's, decoded in any chunking, in stream order.
    decoder = StreamDecoder()
    by_hand = [f for i in range(0, len(log.stream), 1000) for f in decoder.push(log.stream[i : i + 1000])]
    by_hand += decoder.finish()
    assert [(f.frame, f.t_us) for f in by_hand] == [(f.frame, f.t_us) for f in log.frames]
    assert decoder.stats == log.stream_stats
    assert all(np.array_equal(a.left, b.left) and np.array_equal(a.right, b.right) for a, b in zip(by_hand, log.frames))
    assert log.truncated is None
    assert log.warnings == () and log.ignored_topics == () and log.ignored_messages == 0
    assert {"/fpga/features", "/odom", "/rig"} <= set(log.topics)


def test_the_odometry_is_what_the_replay_counts() -> None:
    log = experiment()
    assert log.odometry.dtype == ODOMETRY_DTYPE
    replayed = stereonav.replay(EXPERIMENT_LOG, skip_phase1=True)
    assert len(log.odometry) == replayed.summary["counts"]["odometry"] > 0
    # As logged: the committed log's samples are in time order, finite, read-only.
    assert np.all(np.diff(log.odometry["t_us"].astype(np.int64)) >= 0)
    for field in ("vx", "vy", "vtheta"):
        assert np.all(np.isfinite(log.odometry[field]))
    assert not log.odometry.flags.writeable


def test_the_logged_rig_is_the_rig_file() -> None:
    log = experiment()
    assert log.rig_json is not None
    assert {"camera", "mount", "estimate", "prior", "noise"} <= set(json.loads(log.rig_json))
    assert log.rig == load_rig(EXPERIMENT_RIG)


def test_the_truth_has_a_pose_per_frame_and_the_lamps() -> None:
    log = experiment()
    truth = log.truth
    assert isinstance(truth, LogTruth)
    assert truth.trajectory.dtype == TRAJECTORY_DTYPE
    assert len(truth.trajectory) == len(log.frames) == EXPERIMENT_FRAMES
    assert sorted(truth.trajectory["t_us"].tolist()) == sorted(f.t_us for f in log.frames)
    assert truth.landmark_ids.dtype == np.uint64 and truth.landmark_ids.shape == (LAMPS,)
    assert truth.landmarks.dtype == np.float64 and truth.landmarks.shape == (LAMPS, 3)
    assert len(set(truth.landmark_ids.tolist())) == LAMPS
    assert isinstance(truth.camera, Camera)
    rig = log.rig
    assert rig is not None
    # The truth is near the nominal rig, not equal to it (the rig file is what the user has).
    assert truth.camera.f == pytest.approx(rig.nominal.f, rel=0.1)
    assert truth.camera.baseline == pytest.approx(rig.nominal.baseline, rel=0.1)
    for array in (truth.trajectory, truth.landmark_ids, truth.landmarks):
        assert not array.flags.writeable
    assert "961 frames" in repr(log) and "5 landmarks" in repr(truth)


def test_a_simulated_run_reads_back_as_simulated(tmp_path: pathlib.Path) -> None:
    sim = stereonav.simulate(SCENARIOS / "paper-square.toml")
    path = tmp_path / "square.mcap"
    sim.write_log(path)
    log = read_log(path)
    assert log.stream == sim.stream
    np.testing.assert_array_equal(log.odometry, sim.odometry)
    truth = log.truth
    assert truth is not None
    np.testing.assert_array_equal(truth.trajectory, sim.trajectory)
    np.testing.assert_array_equal(truth.landmarks, sim.landmarks)
    np.testing.assert_array_equal(truth.landmark_ids, np.arange(len(sim.landmarks)))
    assert truth.camera == sim.camera
    rig_file = tmp_path / "square.rig.toml"
    rig_file.write_text(sim.rig_toml)
    assert log.rig == load_rig(rig_file)


def test_a_log_cut_short_reads_as_far_as_it_goes(tmp_path: pathlib.Path) -> None:
    data = EXPERIMENT_LOG.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])
    log = read_log(cut)
    assert isinstance(log.truncated, str) and log.truncated
    assert 0 < len(log.frames) < EXPERIMENT_FRAMES
    assert 0 < len(log.odometry) < len(experiment().odometry)
    assert experiment().stream.startswith(log.stream)
    assert "truncated" in repr(log)


@pytest.mark.skipif(not FOREIGN_LOG.is_file(), reason=f"no foreign MCAP file {FOREIGN_LOG}")
def test_a_foreign_mcap_file_is_not_a_vehicle_log() -> None:
    with pytest.raises(InputError, match=re.escape(f"{FOREIGN_LOG} is not a vehicle log")) as info:
        read_log(FOREIGN_LOG)
    message = str(info.value)
    assert "no /fpga/features or /odom channel" in message and "(its topics: " in message
    assert "\n" not in message
    # The same message as the replay's.
    with pytest.raises(InputError) as replayed:
        stereonav.replay(FOREIGN_LOG, EXPERIMENT_RIG)
    assert str(replayed.value) == message


def test_a_missing_log_names_the_path(tmp_path: pathlib.Path) -> None:
    missing = tmp_path / "no-such-log.mcap"
    with pytest.raises(InputError, match=re.escape(str(missing))) as info:
        read_log(missing)
    assert isinstance(info.value, stereonav.Error) and isinstance(info.value, ValueError)
    assert isinstance(info.value.__cause__, FileNotFoundError)


def test_files_that_are_not_mcap_are_named(tmp_path: pathlib.Path) -> None:
    text = tmp_path / "notes.txt"
    text.write_text("not a log\n")
    with pytest.raises(InputError, match=re.escape(f"{text} is not an MCAP file")):
        read_log(text)
    with pytest.raises(InputError, match=re.escape(f"{EXPERIMENT_RIG} is not an MCAP file")):
        read_log(EXPERIMENT_RIG)
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    with pytest.raises(InputError, match="empty.mcap is not an MCAP file: it is empty"):
        read_log(empty)
    with pytest.raises(InputError) as info:
        read_log(tmp_path)
    assert isinstance(info.value.__cause__, OSError)


def test_wrong_argument_types_are_named() -> None:
    with pytest.raises(InputTypeError, match="path must be a str or os.PathLike, got int"):
        read_log(42)  # type: ignore[arg-type]
    with pytest.raises(InputTypeError, match="path must be a str or os.PathLike, got bytes"):
        read_log(b"x.mcap")  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        read_log()  # type: ignore[call-arg]


def write_log(path: pathlib.Path, rig: bytes | None) -> list[bytes]:
    """A small log written with the reference Python ``mcap`` writer: three packets in odd
    chunks, odometry, an optional ``/rig`` message and a foreign topic. Returns the packets."""
    mcap_writer = pytest.importorskip("mcap.writer")
    features = np.array([(160, 320, 1 << 20), (400, 80, 7)], dtype=stereonav.FEATURE_DTYPE)
    packets = [
        stereonav.encode_packet(features, features[:1], frame=i, t_us=50_000 * i) for i in range(3)
    ]
    stream = b"".join(packets)
    with path.open("wb") as f:
        w = mcap_writer.Writer(f)
        w.start(profile="", library="test_read_log")
        rig_schema = w.register_schema("stereonav.Rig", "jsonschema", b"{}")
        odom = w.register_channel("/odom", "json", 0)
        chunks = w.register_channel("/fpga/features", "stereonav.fpga-link.v1", 0)
        rig_channel = w.register_channel("/rig", "json", rig_schema)
        other = w.register_channel("/diagnostics", "json", 0)
        if rig is not None:
            w.add_message(rig_channel, 0, rig, 0, 0)
        for k, at in enumerate(range(0, len(stream), 37)):
            t = 1000 * k
            w.add_message(chunks, t, stream[at : at + 37], t, k)
            sample = {"t_us": 40_000 - 1000 * k, "vx": 0.5, "vy": 0.0, "vtheta": 0.01 * k}
            w.add_message(odom, t, json.dumps(sample).encode(), t, k)
        w.add_message(other, 0, b'{"ok": true}', 0, 0)
        w.finish()
    return packets


def test_a_log_from_another_writer_reads_as_logged(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "small.mcap"
    packets = write_log(path, rig=None)
    log = read_log(path)
    assert log.stream == b"".join(packets)
    assert log.chunks == -(-len(log.stream) // 37)
    assert [(f.frame, f.t_us) for f in log.frames] == [(0, 0), (1, 50_000), (2, 100_000)]
    assert log.stream_stats == StreamStats(packets=3, corrupt=0, lost=0, bytes_skipped=0)
    # As logged: odometry going back in time stays in log order.
    assert log.odometry["t_us"].tolist() == [40_000 - 1000 * k for k in range(log.chunks)]
    np.testing.assert_array_equal(log.odometry["vtheta"], 0.01 * np.arange(log.chunks))
    assert log.rig_json is None and log.rig is None and log.truth is None
    assert log.ignored_topics == ("/diagnostics",) and log.ignored_messages == 1


def test_a_bad_rig_message_is_named_when_asked_for(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "bad-rig.mcap"
    text = json.dumps({"camera": {"width": 752}})
    write_log(path, rig=text.encode())
    log = read_log(path)
    assert log.rig_json == text
    with pytest.raises(InputError, match=re.escape(f"{path} /rig: [mount]: missing table")):
        log.rig  # the property parses the message
    assert len(log.frames) == 3
