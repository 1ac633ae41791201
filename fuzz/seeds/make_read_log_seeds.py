"""Regenerates the seed corpus of the read_log fuzz target (fuzz/seeds/read_log/*.mcap): three
small vehicle logs of the reference Python ``mcap`` writer, with zstd, lz4 and uncompressed
400-byte chunks, message indexes and a summary, so that the fuzzer starts from valid files:

    .venv/bin/python fuzz/seeds/make_read_log_seeds.py
"""

from __future__ import annotations

import json
import pathlib

from mcap.writer import CompressionType, Writer

OUT = pathlib.Path(__file__).resolve().parent / "read_log"


def main() -> None:
    OUT.mkdir(exist_ok=True)
    kinds = [("zstd", CompressionType.ZSTD), ("lz4", CompressionType.LZ4), ("none", CompressionType.NONE)]
    for name, compression in kinds:
        with (OUT / f"small-{name}.mcap").open("wb") as f:
            w = Writer(f, chunk_size=400, compression=compression)
            w.start(profile="", library="seed")
            schema = w.register_schema("stereonav.Odometry", "jsonschema", b'{"type":"object"}')
            odom = w.register_channel("/odom", "json", schema)
            features = w.register_channel("/fpga/features", "stereonav.fpga-link.v1", 0)
            for i in range(30):
                t = 1_000_000_000 + i * 10_000_000
                sample = {"t_us": t // 1000, "vx": 0.5, "vy": 0.0, "vtheta": 0.01}
                w.add_message(odom, t, json.dumps(sample).encode(), t, i)
                if i % 5 == 0:
                    w.add_message(features, t + 1000, bytes(range(i, i + 40)), t + 1000, i)
            w.finish()


if __name__ == "__main__":
    main()
