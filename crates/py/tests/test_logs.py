"""The committed vehicle logs open with the third-party Python `mcap` reader, CRCs checked,
and carry the topics of vehicle-interfaces.md section 4 with valid JSON messages."""

from __future__ import annotations

import json
import pathlib

import pytest

mcap_reader = pytest.importorskip("mcap.reader")

LOGS = sorted((pathlib.Path(__file__).resolve().parents[3] / "fixtures" / "logs").glob("*.mcap"))


def test_the_paper_logs_are_committed() -> None:
    names = {p.stem for p in LOGS}
    assert {"paper-calibration", "paper-square", "paper-experiment"} <= names, names


@pytest.mark.parametrize("path", LOGS, ids=[p.stem for p in LOGS])
def test_log_reads_with_crc_validation(path: pathlib.Path) -> None:
    with path.open("rb") as f:
        reader = mcap_reader.make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None
        channels = {c.topic: c for c in summary.channels.values()}
        assert channels["/fpga/features"].message_encoding == "stereonav.fpga-link.v1"
        assert channels["/odom"].message_encoding == "json"
        odom_schema = summary.schemas[channels["/odom"].schema_id]
        assert odom_schema.name == "stereonav.Odometry" and odom_schema.encoding == "jsonschema"
        json.loads(odom_schema.data)  # a real JSON Schema document
        counts = {"/fpga/features": 0, "/odom": 0}
        last_t = -1
        for _schema, channel, message in reader.iter_messages(log_time_order=False):
            if channel.topic == "/odom":
                sample = json.loads(message.data)
                assert set(sample) == {"t_us", "vx", "vy", "vtheta"}
                assert isinstance(sample["t_us"], int) and sample["t_us"] >= last_t
                last_t = sample["t_us"]
            elif channel.topic == "/rig":
                assert {"camera", "mount", "estimate", "prior", "noise"} <= set(json.loads(message.data))
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
        assert counts["/fpga/features"] > 0 and counts["/odom"] > 0
