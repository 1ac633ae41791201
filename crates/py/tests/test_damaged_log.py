"""Damaged vehicle logs read from Python (``stereonav.read_log``): a log written by the reference
Python ``mcap`` writer (zstd, 32 KiB chunks), then damaged as a vehicle damages it (a bit flipped
in a chunk, the magic hit, the file cut inside a chunk), is read past the damage, and
``VehicleLog.damage`` says what was lost and where."""

from __future__ import annotations

import pathlib
from typing import Optional

import pytest

import stereonav
from stereonav import InputError, LogDamage, LostSpan

mcap_reader = pytest.importorskip("mcap.reader")
mcap_writer = pytest.importorskip("mcap.writer")

import mcap_copy  # noqa: E402  (after the skip: it imports mcap)

ROOT = pathlib.Path(__file__).resolve().parents[3]
LOG = ROOT / "fixtures" / "logs" / "paper-experiment.mcap"
ODOMETRY = 4801


def rewrite(dst: pathlib.Path) -> None:
    """The committed log, every message, rewritten by the Python writer in 32 KiB zstd chunks."""
    mcap_copy.rewrite(LOG, dst)


def chunks(path: pathlib.Path) -> list[tuple[int, int, int]]:
    """Each chunk record's ``(offset, end, /odom messages)``: the file's top-level records walked
    (opcode u8, length u64, body), the counts from the message index records after each chunk,
    the channel ids from the summary."""
    with path.open("rb") as f:
        summary = mcap_reader.make_reader(f).get_summary()
    assert summary is not None
    odom = {c.id for c in summary.channels.values() if c.topic == "/odom"}
    data = path.read_bytes()
    out: list[tuple[int, int, int]] = []
    at = 8
    while at + 9 <= len(data):
        opcode = data[at]
        end = at + 9 + int.from_bytes(data[at + 1 : at + 9], "little")
        if opcode == 0x06:
            out.append((at, end, 0))
        elif opcode == 0x07 and out and int.from_bytes(data[at + 9 : at + 11], "little") in odom:
            a, b, n = out[-1]
            out[-1] = (a, b, n + int.from_bytes(data[at + 11 : at + 15], "little") // 16)
        elif opcode == 0x0F:
            break
        at = end
    return out


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    path = tmp_path_factory.mktemp("damaged") / "python-written.mcap"
    rewrite(path)
    return path


def damaged(src: pathlib.Path, dst: pathlib.Path, flips: list[int], cut: Optional[int] = None) -> pathlib.Path:
    data = bytearray(src.read_bytes())
    for at in flips:
        data[at] ^= 0x10
    dst.write_bytes(bytes(data[:cut]) if cut is not None else bytes(data))
    return dst


def test_an_intact_log_has_no_damage(written: pathlib.Path) -> None:
    log = stereonav.read_log(written)
    assert isinstance(log.damage, LogDamage)
    assert not log.damage.damaged
    assert log.damage.spans == [] and log.damage.spans_total == 0
    assert log.damage.summary == "intact" and log.damage.summary_problem is None
    assert log.damage.messages_lost == {}
    assert len(log.odometry) == ODOMETRY
    assert "none" in repr(log.damage)


def test_one_flipped_bit_is_mended(written: pathlib.Path, tmp_path: pathlib.Path) -> None:
    layout = chunks(written)
    start, end, _ = layout[len(layout) // 2]
    log = stereonav.read_log(damaged(written, tmp_path / "one-flip.mcap", [(start + end) // 2]))
    assert log.damage.repaired_chunks == 1 and log.damage.spans_total == 0
    assert len(log.odometry) == ODOMETRY


def test_a_chunk_it_cannot_mend_costs_only_that_chunk(written: pathlib.Path, tmp_path: pathlib.Path) -> None:
    layout = chunks(written)
    assert len(layout) > 10
    for k in (0, len(layout) // 2):
        start, end, odom_in_chunk = layout[k]
        assert odom_in_chunk > 0
        # Two flipped bits in one chunk: no single bit explains them, the chunk is lost.
        mid = (start + end) // 2
        path = damaged(written, tmp_path / f"flip-{k}.mcap", [mid, mid + 40])
        log = stereonav.read_log(path)
        assert log.damage.damaged
        assert log.damage.spans_total == 1 and log.damage.chunks_lost == 1
        span = log.damage.spans[0]
        assert isinstance(span, LostSpan)
        assert span.offset == start and span.bytes == end - start
        assert span.exact_times and span.start_ns is not None and span.end_ns is not None
        assert span.start_ns <= span.end_ns
        assert span.messages is not None and span.messages["/odom"] == odom_in_chunk
        assert "CRC" in span.why or "decompress" in span.why
        # Everything else is read, the first chunk's channels included (from the summary).
        assert len(log.odometry) == ODOMETRY - odom_in_chunk
        assert log.damage.messages_lost is not None
        assert log.damage.messages_lost["/odom"] == odom_in_chunk
        assert len(log.frames) > 900
        assert log.truncated is None
        assert "damaged" in repr(log)


def test_a_damaged_magic_is_read_past(written: pathlib.Path, tmp_path: pathlib.Path) -> None:
    log = stereonav.read_log(damaged(written, tmp_path / "magic.mcap", [1]))
    assert log.damage.header_damaged and log.damage.damaged
    assert log.damage.spans_total == 0
    assert len(log.odometry) == ODOMETRY


def test_a_log_cut_inside_a_chunk_keeps_every_whole_chunk(written: pathlib.Path, tmp_path: pathlib.Path) -> None:
    layout = chunks(written)
    start, end, _ = layout[len(layout) // 2]
    log = stereonav.read_log(damaged(written, tmp_path / "cut.mcap", [], cut=(start + end) // 2))
    whole = sum(n for _, e, n in layout if e <= (start + end) // 2)
    assert len(log.odometry) >= whole > 0
    assert log.damage.cut and log.damage.summary == "absent"
    assert log.truncated is not None and "cut short" in log.truncated
    assert "cut short" in log.damage.spans[-1].why
    assert {"/fpga/features", "/odom"} <= set(log.topics)


# The slow tier (docs/testing.md): ten copies with up to ten flips each, every damaged chunk
# searched bit by bit for a mend (vehicle-log's `repair`, bounded by its work limit), 100 s.
@pytest.mark.slow
def test_many_flips_never_raise_and_lose_at_most_the_chunks_they_hit(
    written: pathlib.Path, tmp_path: pathlib.Path
) -> None:
    import random

    layout = chunks(written)
    size = written.stat().st_size
    rng = random.Random(11)
    for copy in range(10):
        flips = [rng.randrange(size) for _ in range(rng.randint(1, 10))]
        log = stereonav.read_log(damaged(written, tmp_path / f"many-{copy}.mcap", flips))
        spared = sum(n for a, b, n in layout if not any(a <= f < b for f in flips))
        assert len(log.odometry) >= spared, (copy, flips)


def test_files_that_are_not_mcap_are_refused(tmp_path: pathlib.Path) -> None:
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 20)
    with pytest.raises(InputError, match="is not an MCAP file"):
        stereonav.read_log(junk)
