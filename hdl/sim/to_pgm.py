#!/usr/bin/env python3
"""Turns an image that `stereonav harris` reads but the testbench does not (an 8-bit grayscale
PNG, an ASCII PGM) into a binary PGM for hdl/sim/board_tb.cpp. Standard library only.

    python3 hdl/sim/to_pgm.py IMAGE OUT.pgm

Exits 0 having written OUT.pgm, or 1 with stereonav's kind of message (`stereonav: error: ...`)
for what stereonav refuses too (colour, 16-bit) or what this reader does not handle (interlaced
or low-bit-depth PNG: stereonav reads those, this reports them as unsupported).
"""

from __future__ import annotations

import struct
import sys
import zlib
from pathlib import Path

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
# PNG colour types and the image crate's names for them at 8 and 16 bits.
PNG_COLOURS = {0: ("L8", "L16"), 2: ("Rgb8", "Rgb16"), 3: ("Rgb8", "Rgb8"), 4: ("La8", "La16"), 6: ("Rgba8", "Rgba16")}


class Refused(Exception):
    """The image cannot be given to the board, with stereonav's wording."""


def unfilter(raw: bytes, width: int, height: int) -> bytes:
    """PNG's five row filters on one byte per pixel."""
    out, prev, at = bytearray(), bytearray(width), 0
    for _ in range(height):
        kind, line = raw[at], bytearray(raw[at + 1 : at + 1 + width])
        at += 1 + width
        if kind == 1:
            for x in range(1, width):
                line[x] = (line[x] + line[x - 1]) & 255
        elif kind == 2:
            line = bytearray((a + b) & 255 for a, b in zip(line, prev))
        elif kind == 3:
            for x in range(width):
                left = line[x - 1] if x else 0
                line[x] = (line[x] + ((left + prev[x]) >> 1)) & 255
        elif kind == 4:
            for x in range(width):
                a = line[x - 1] if x else 0
                b, c = prev[x], prev[x - 1] if x else 0
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[x] = (line[x] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        elif kind != 0:
            raise ValueError(f"bad PNG filter {kind}")
        out += line
        prev = line
    return bytes(out)


def read_png_gray8(data: bytes, name: str) -> tuple[int, int, bytes]:
    """An 8-bit grayscale, non-interlaced PNG as (width, height, pixels)."""
    pos, idat, header = len(PNG_SIGNATURE), bytearray(), None
    while pos + 8 <= len(data):
        (n,) = struct.unpack(">I", data[pos : pos + 4])
        kind, chunk = data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + n]
        pos += 12 + n
        if kind == b"IHDR" and len(chunk) == 13:
            header = struct.unpack(">IIBBBBB", chunk)
        elif kind == b"IDAT":
            idat += chunk
        elif kind == b"IEND":
            break
    if header is None:
        raise Refused(f"{name} is not a readable PGM or PNG image: no PNG header")
    width, height, depth, colour, _, _, interlace = header
    names = PNG_COLOURS.get(colour)
    if names is None:
        raise Refused(f"{name} is not a readable PGM or PNG image: bad PNG colour type {colour}")
    if colour != 0 or depth == 16:
        kind = names[1] if depth == 16 else names[0]
        raise Refused(f"{name} is {kind}, expected 8-bit grayscale (convert it first, e.g. to an 8-bit PGM)")
    if depth != 8 or interlace != 0:
        raise Refused(f"{name}: hdl/sim.sh reads 8-bit non-interlaced PNG only (convert it to a binary PGM)")
    try:
        pixels = unfilter(zlib.decompress(bytes(idat)), width, height)
    except (zlib.error, ValueError, IndexError) as e:
        raise Refused(f"{name} is not a readable PGM or PNG image: {e}") from e
    if len(pixels) != width * height:
        raise Refused(f"{name} is not a readable PGM or PNG image: failed to fill whole buffer")
    return width, height, pixels


def read_ascii_pgm(data: bytes, name: str) -> tuple[int, int, bytes]:
    """An ASCII PGM (P2), MAXVAL 1..=255 scaled to 0..=255 in f32 as the image crate does."""
    words = []
    for line in data[2:].split(b"\n"):
        words += line.split(b"#", 1)[0].split()
    try:
        width, height, maxval = int(words[0]), int(words[1]), int(words[2])
        values = [int(w) for w in words[3 : 3 + width * height]]
    except (IndexError, ValueError) as e:
        raise Refused(f"{name} is not a readable PGM or PNG image: {e}") from e
    if maxval == 0:
        raise Refused(f"{name} is not a readable PGM or PNG image: Format error decoding Pnm: Image MAXVAL is zero")
    if maxval > 255:
        raise Refused(f"{name} is L16, expected 8-bit grayscale (convert it first, e.g. to an 8-bit PGM)")
    if len(values) != width * height:
        raise Refused(f"{name} is not a readable PGM or PNG image: failed to fill whole buffer")
    if maxval != 255:
        factor = struct.unpack("f", struct.pack("f", 255.0 / maxval))[0]
        values = [min(255, round_half_away(f32(f32(v) * factor))) for v in values]
    return width, height, bytes(values)


def f32(value: float) -> float:
    return struct.unpack("f", struct.pack("f", value))[0]


def round_half_away(value: float) -> int:
    return int(value + 0.5) if value >= 0 else -int(-value + 0.5)


def main() -> int:
    source, target = sys.argv[1], sys.argv[2]
    try:
        data = Path(source).read_bytes()
    except OSError as e:
        print(f"stereonav: error: cannot open image {source}: {e.strerror}", file=sys.stderr)
        return 1
    try:
        if data.startswith(PNG_SIGNATURE):
            width, height, pixels = read_png_gray8(data, source)
        elif data[:2] == b"P2":
            width, height, pixels = read_ascii_pgm(data, source)
        else:
            raise Refused(f"{source} is not a readable PGM or PNG image: hdl/sim.sh reads PGM and 8-bit gray PNG")
    except Refused as e:
        print(f"stereonav: error: {e}", file=sys.stderr)
        return 1
    Path(target).write_bytes(b"P5\n%d %d\n255\n" % (width, height) + pixels)
    return 0


if __name__ == "__main__":
    sys.exit(main())
