"""A vehicle log written by another tool: the committed paper-experiment log rewritten with the
reference Python ``mcap`` writer (no compression, small chunks, no summary offsets, no /rig, no
truth, the board's byte stream cut at other places, odometry channels declared without a
schema). The replay must give exactly what the original log gives."""

from __future__ import annotations

import pathlib
import random

import pytest

import stereonav

mcap_reader = pytest.importorskip("mcap.reader")
mcap_writer = pytest.importorskip("mcap.writer")

ROOT = pathlib.Path(__file__).resolve().parents[3]
LOG = ROOT / "fixtures" / "logs" / "paper-experiment.mcap"
RIG = ROOT / "fixtures" / "logs" / "paper-experiment.rig.toml"


def rewrite(src: pathlib.Path, dst: pathlib.Path, seed: int) -> None:
    stream = bytearray()
    odometry: list[tuple[int, bytes]] = []
    first_time = None
    with src.open("rb") as f:
        for _schema, channel, message in mcap_reader.make_reader(f).iter_messages(log_time_order=False):
            if first_time is None:
                first_time = message.log_time
            if channel.topic == "/fpga/features":
                stream += message.data
            elif channel.topic == "/odom":
                odometry.append((message.log_time, message.data))
    assert first_time is not None and stream and odometry
    rng = random.Random(seed)
    chunks: list[bytes] = []
    at = 0
    while at < len(stream):
        n = rng.randint(1, 3000)
        chunks.append(bytes(stream[at : at + n]))
        at += n
    # Spread the chunks over the log's time span, odometry in between, by log time.
    span = odometry[-1][0] - first_time
    timed = [(first_time + span * i // len(chunks), 0, c) for i, c in enumerate(chunks)]
    timed += [(t, 1, d) for t, d in odometry]
    timed.sort(key=lambda r: (r[0], r[1]))
    with dst.open("wb") as f:
        w = mcap_writer.Writer(
            f,
            chunk_size=4096,
            compression=mcap_writer.CompressionType.NONE,
            use_summary_offsets=False,
        )
        w.start(profile="", library="another-tool 0.1")
        odom = w.register_channel("/odom", "json", 0)
        features = w.register_channel("/fpga/features", "stereonav.fpga-link.v1", 0)
        other = w.register_channel("/diagnostics", "json", 0)
        for seq, (t, kind, data) in enumerate(timed):
            w.add_message(features if kind == 0 else odom, t, data, t, seq)
            if seq % 500 == 0:
                w.add_message(other, t, b'{"ok": true}', t, seq)
        w.finish()


@pytest.mark.parametrize("seed", [1, 2])
def test_a_log_written_by_another_tool_replays_like_the_original(
    tmp_path: pathlib.Path, seed: int
) -> None:
    foreign = tmp_path / "foreign.mcap"
    rewrite(LOG, foreign, seed)
    original = stereonav.replay(LOG, RIG, skip_phase1=True)
    replayed = stereonav.replay(foreign, RIG, skip_phase1=True)
    assert replayed.truth is None  # no /truth in the rewritten log
    assert replayed.summary["frames"] == original.summary["frames"] == 961
    assert replayed.summary["landmarks"] == original.summary["landmarks"]
    assert replayed.summary["camera"] == original.summary["camera"]
    assert replayed.summary["pose"] == original.summary["pose"]
    assert (replayed.trajectory == original.trajectory).all()
    assert len(replayed.landmarks) == 5


@pytest.mark.parametrize("seed", [1, 2])
def test_the_whole_method_on_a_log_written_by_another_tool(
    tmp_path: pathlib.Path, seed: int
) -> None:
    # No flag: phase 1's batch hands over, phase 2 maps, bit for bit as on the original.
    foreign = tmp_path / "foreign.mcap"
    rewrite(LOG, foreign, seed)
    original = stereonav.replay(LOG, RIG)
    replayed = stereonav.replay(foreign, RIG)
    assert original.phase_switch_t_us is not None
    assert replayed.phase_switch_t_us == original.phase_switch_t_us
    assert replayed.summary["camera"] == original.summary["camera"]
    assert (replayed.trajectory == original.trajectory).all()
    assert len(replayed.landmarks) == 5


def test_a_real_vehicle_log_written_by_another_tool(tmp_path: pathlib.Path) -> None:
    # The paper's drive with a 1 % odometry scale, a yaw-rate bias and a 12 ms board clock
    # offset (fixtures/scenarios/paper-experiment-vehicle.toml), simulated, then rewritten by
    # the reference writer with other chunks: V is estimated from it as from the original,
    # and to within the bounds.
    scenario = ROOT / "fixtures" / "scenarios" / "paper-experiment-vehicle.toml"
    rig = ROOT / "fixtures" / "scenarios" / "paper-experiment-vehicle.rig.toml"
    sim = stereonav.simulate(scenario, seed=3)
    original_log = tmp_path / "vehicle.mcap"
    sim.write_log(original_log)
    foreign = tmp_path / "foreign-vehicle.mcap"
    rewrite(original_log, foreign, 7)
    original = stereonav.replay(original_log, rig)
    replayed = stereonav.replay(foreign, rig)
    assert replayed.summary["vehicle"] == original.summary["vehicle"]
    assert (replayed.trajectory == original.trajectory).all()
    vehicle = replayed.summary["vehicle"]
    assert abs(vehicle["odom_scale"]["value"] - 1.01) <= 0.006
    assert abs(vehicle["odom_yaw_bias"]["value"] - 0.002) <= 0.0005
    assert vehicle["odom_yaw_scale"]["sigma"] == 0.0  # not estimated: nominal
    assert vehicle["odom_yaw_scale"]["value"] == 1.0
    assert abs(replayed.summary["camera"]["baseline"]["value"] - 0.1202) <= 0.0005
