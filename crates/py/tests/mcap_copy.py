"""A vehicle log copied by the reference Python ``mcap`` writer (its own chunking, CRCs,
indexes and summary): the tests' "other writer" of the same messages."""

from __future__ import annotations

import pathlib

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer


def rewrite(
    source: pathlib.Path,
    target: pathlib.Path,
    *,
    chunk_size: int = 32 * 1024,
    compression: CompressionType = CompressionType.ZSTD,
) -> pathlib.Path:
    """Every schema, channel and message of ``source``, in file order with its times and
    sequence number, written to ``target`` in chunks of ``chunk_size`` uncompressed bytes."""
    with source.open("rb") as src, target.open("wb") as dst:
        writer = Writer(dst, chunk_size=chunk_size, compression=compression)
        writer.start(profile="", library="mcap-python (stereonav tests)")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in make_reader(src).iter_messages(log_time_order=False):
            if channel.id not in channels:
                schema_id = 0
                if schema is not None and schema.id != 0:
                    if schema.id not in schemas:
                        schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
                    schema_id = schemas[schema.id]
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schema_id, dict(channel.metadata)
                )
            writer.add_message(
                channels[channel.id], message.log_time, message.data, message.publish_time, message.sequence
            )
        writer.finish()
    return target
