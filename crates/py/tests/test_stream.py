"""The board's feature stream from Python: decoding in any chunking, corruption, errors."""

from __future__ import annotations

import zlib

import numpy as np
import pytest

import stereonav
from stereonav import FEATURE_DTYPE, StreamDecoder, encode_packet


def features(rng: np.random.Generator, n: int) -> np.ndarray:
    out = np.zeros(n, dtype=FEATURE_DTYPE)
    out["x_q4"] = rng.integers(0, 1 << 16, n)
    out["y_q4"] = rng.integers(0, 1 << 16, n)
    out["r"] = rng.integers(-(1 << 31), 1 << 31, n)
    return out


def stream(seed: int, frames: int, n: int = 50) -> tuple[bytes, list[tuple[int, np.ndarray, np.ndarray]]]:
    rng = np.random.default_rng(seed)
    out, sent = b"", []
    for i in range(frames):
        left, right = features(rng, n), features(rng, n + 1)
        out += encode_packet(left, right, frame=100 + i, t_us=50_000 * i, right_overflow=i % 2 == 1)
        sent.append((100 + i, left, right))
    return out, sent


def decode(data: bytes, chunk: int) -> tuple[list[stereonav.Frame], stereonav.StreamStats]:
    decoder = StreamDecoder()
    frames = []
    for i in range(0, len(data), chunk):
        frames += decoder.push(data[i : i + chunk])
    frames += decoder.finish()
    return frames, decoder.stats


@pytest.mark.parametrize("chunk", [1, 7, 1000, 1 << 20])
def test_round_trip_in_any_chunking(chunk: int) -> None:
    data, sent = stream(1, 5)
    frames, stats = decode(data, chunk)
    assert stats == (5, 0, 0, 0)
    for got, (frame, left, right) in zip(frames, sent):
        assert got.frame == frame
        assert got.left.dtype == FEATURE_DTYPE
        np.testing.assert_array_equal(got.left, left)
        np.testing.assert_array_equal(got.right, right)
        assert got.right_overflow == (frame % 2 == 1) and not got.left_overflow


def test_packet_layout_matches_the_icd() -> None:
    left = np.array([(0x0102, 0x0304, -2)], dtype=FEATURE_DTYPE)
    packet = encode_packet(left, left[:0], frame=0x01020304, t_us=5, left_overflow=True)
    assert packet[:4] == bytes([0x5A, 0xA5, 0x3C, 0xC3])
    assert packet[4:6] == bytes([1, 1])  # version, flags
    assert packet[6:12] == bytes([1, 0, 0, 0, 0, 0])  # n_left, n_right, reserved
    assert packet[12:16] == bytes([4, 3, 2, 1])
    assert packet[24:32] == bytes([2, 1, 4, 3, 0xFE, 0xFF, 0xFF, 0xFF])
    assert int.from_bytes(packet[-4:], "little") == zlib.crc32(packet[4:-4])


def test_corruption_loss_and_garbage_are_counted() -> None:
    data, sent = stream(2, 4, n=3)
    size = len(data) // 4
    bad = bytearray(b"garbage!" + data)
    bad[8 + size + 30] ^= 0x10  # a bit flip inside packet 2
    frames, stats = decode(bytes(bad), 5)
    assert [f.frame for f in frames] == [100, 102, 103]
    assert frames[1].lost_before == 1
    assert stats.packets == 3 and stats.corrupt == 1 and stats.lost == 1
    assert stats.bytes_skipped == 8 + size


def test_truncated_stream_ends_cleanly() -> None:
    data, _ = stream(3, 2)
    decoder = StreamDecoder()
    assert len(decoder.push(data[:-10])) == 1
    assert decoder.buffered > 0
    assert decoder.finish() == []
    assert decoder.stats.corrupt == 1 and decoder.buffered == 0


def test_accepts_bytes_like_inputs() -> None:
    data, _ = stream(4, 1)
    for form in (bytearray(data), memoryview(data), np.frombuffer(data, np.uint8)):
        decoder = StreamDecoder()
        assert len(decoder.push(form)) == 1


def test_bad_arguments_raise_typed_errors() -> None:
    decoder = StreamDecoder()
    with pytest.raises(TypeError, match="got str"):
        decoder.push("5aa53cc3")  # type: ignore[arg-type]
    with pytest.raises(stereonav.InputTypeError, match="float64"):
        decoder.push(np.zeros(4))
    empty = np.zeros(0, dtype=FEATURE_DTYPE)
    with pytest.raises(stereonav.InputError, match="1024 features"):
        encode_packet(np.zeros(1024, dtype=FEATURE_DTYPE), empty, frame=0, t_us=0)
    with pytest.raises(ValueError, match="frame 4294967296"):
        encode_packet(empty, empty, frame=1 << 32, t_us=0)
    with pytest.raises(TypeError, match="FEATURE_DTYPE"):
        encode_packet(np.zeros(3, np.int64), empty, frame=0, t_us=0)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="int"):
        encode_packet(empty, empty, frame=1.5, t_us=0)  # type: ignore[arg-type]


def test_random_bytes_never_crash() -> None:
    rng = np.random.default_rng(5)
    decoder = StreamDecoder()
    for _ in range(50):
        decoder.push(rng.integers(0, 256, int(rng.integers(0, 3000)), dtype=np.uint8).tobytes())
    decoder.finish()
    assert decoder.buffered == 0
