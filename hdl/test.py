#!/usr/bin/env python3
"""The board's HDL (hdl/rtl/) against harris-core, bit for bit (board-icd.md section 4).

    python3 hdl/test.py [--slow] [--stereonav PATH] [--jobs N] [-k SUBSTRING]

Each case runs `bash hdl/sim.sh IMAGE THRESHOLD MAX_FEATURES` and
`stereonav harris IMAGE --threshold THRESHOLD --max-features MAX_FEATURES` and compares their
standard output and exit status (and, for the register errors, their messages). The packet
cases compare the encoder's byte stream (`bash hdl/sim.sh --packet`) with
`stereonav fpga emulate`'s, byte for byte, and decode it with `stereonav fpga decode`
(fpga-link's decoder): every frame's features must equal `stereonav harris` on its images.

The fast tier (the default, run by `bash scripts/test.sh`) takes well under a minute on two
cores: the integer ranges' edges (THRESHOLD at i32::MIN, -1, 0, 1, i32::MAX; MAX_FEATURES at 1
and 1023 with overflow), every register error, images of 16 pixels and of 4095, one-row and
one-column images (refused, as harris-core refuses them), random and adversarial images (noise,
saturated noise, plateaus and checkerboards full of ties), synthetic lamps, crops of a real
EuRoC frame, an irregular pixel stream and link, and packets. `--slow` (run by
`bash scripts/test.sh --slow`) runs whole 752x480 frames: every real EuRoC frame of
../shared/data/euroc-v101-stereo (skipped, with a message, where ../shared is absent) at many
registers, the ceiling-lamp fixture, large random images, and the real stereo pairs as packets.

The stereonav binary is --stereonav, else $STEREONAV_BIN, else target/ci/stereonav or
target/release/stereonav. Standard library only. Ends with the line `N passed, N failed`.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import math
import os
import random
import struct
import subprocess
import sys
import tempfile
import zlib
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "hdl" / "sim"))
import to_pgm  # noqa: E402  (hdl/sim/to_pgm.py: the PNG reader sim.sh uses)
SIM = ROOT / "hdl" / "sim.sh"
EUROC = ROOT.parent / "shared" / "data" / "euroc-v101-stereo"
LAMPS_FIXTURE = ROOT / "fixtures" / "images" / "ceiling-lamps.png"
I32_MIN, I32_MAX = -(2**31), 2**31 - 1
DEFAULT_THRESHOLD = 1 << 18  # ICD section 1
MAX_FEATURES_LIMIT = 1023  # ICD section 1


# --- images -----------------------------------------------------------------------------------


@dataclass
class Image:
    width: int
    height: int
    pixels: bytes

    def pgm(self) -> bytes:
        return b"P5\n%d %d\n255\n" % (self.width, self.height) + self.pixels

    def crop(self, x0: int, y0: int, width: int, height: int) -> Image:
        rows = (self.pixels[(y0 + y) * self.width + x0 : (y0 + y) * self.width + x0 + width] for y in range(height))
        return Image(width, height, b"".join(rows))


def read_png_gray8(path: Path) -> Image:
    """An 8-bit grayscale, non-interlaced PNG (EuRoC's frames, the fixture), with sim.sh's reader."""
    width, height, pixels = to_pgm.read_png_gray8(path.read_bytes(), str(path))
    return Image(width, height, pixels)


def png(width: int, height: int, pixels: bytes, colour: int = 0, depth: int = 8, filters: bytes = b"\0") -> bytes:
    """A PNG of raw rows (`pixels` already in the colour type's layout), row filters cycling
    through `filters` (the rows' bytes are written as given: the filters only matter when the
    decoder undoes them, so only filter 0 gives the image `pixels` says)."""
    channels = {0: 1, 2: 3, 4: 2, 6: 4}[colour] * depth // 8
    stride = width * channels
    rows = b"".join(
        filters[y % len(filters) : y % len(filters) + 1] + pixels[y * stride : (y + 1) * stride] for y in range(height)
    )

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    header = struct.pack(">IIBBBBB", width, height, depth, colour, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b"")


def noise(rng: random.Random, width: int, height: int, low: int = 0, high: int = 255) -> Image:
    return Image(width, height, bytes(rng.randint(low, high) for _ in range(width * height)))


def saturated_noise(rng: random.Random, width: int, height: int) -> Image:
    """0 or 255 only: the largest gradients, window sums and responses an image can give."""
    return Image(width, height, bytes(rng.choice((0, 255)) for _ in range(width * height)))


def checkerboard(width: int, height: int, period: int, low: int = 0, high: int = 255) -> Image:
    """Squares of `period` pixels: exactly equal responses everywhere, ties in suppression."""
    return Image(
        width,
        height,
        bytes(high if (x // period + y // period) % 2 else low for y in range(height) for x in range(width)),
    )


def plateaus(rng: random.Random, width: int, height: int) -> Image:
    """Flat rectangles on a flat ground: symmetric corners, equal neighbours (ties)."""
    px = bytearray([rng.randint(0, 255)] * (width * height))
    for _ in range(6):
        x0, y0 = rng.randrange(width), rng.randrange(height)
        x1, y1 = min(width, x0 + rng.randint(1, 12)), min(height, y0 + rng.randint(1, 12))
        value = rng.randint(0, 255)
        for y in range(y0, y1):
            px[y * width + x0 : y * width + x1] = bytes([value]) * (x1 - x0)
    return Image(width, height, bytes(px))


def lamps(rng: random.Random, width: int, height: int, count: int, noise_dn: float = 2.0) -> Image:
    """Small bright Gaussian spots (ceiling lamps) at sub-pixel positions on a dark roof."""
    spots = [
        (rng.uniform(5, width - 6), rng.uniform(5, height - 6), rng.uniform(0.8, 1.6), rng.uniform(120, 250))
        for _ in range(count)
    ]
    px = bytearray()
    for y in range(height):
        for x in range(width):
            value = 30.0 + rng.gauss(0.0, noise_dn)
            for u, v, sigma, peak in spots:
                d2 = (x - u) ** 2 + (y - v) ** 2
                if d2 < 36 * sigma * sigma:
                    value += peak * math.exp(-d2 / (2 * sigma * sigma))
            px.append(max(0, min(255, round(value))))
    return Image(width, height, bytes(px))


def smooth(rng: random.Random, width: int, height: int) -> Image:
    """Low-frequency sums of sines: gentle slopes, few and weak corners."""
    waves = [(rng.uniform(0.02, 0.3), rng.uniform(0.02, 0.3), rng.uniform(0, 6.3)) for _ in range(3)]
    return Image(
        width,
        height,
        bytes(
            max(0, min(255, round(128 + sum(40 * math.sin(a * x + b * y + c) for a, b, c in waves))))
            for y in range(height)
            for x in range(width)
        ),
    )


# --- cases ------------------------------------------------------------------------------------


@dataclass
class HarrisCase:
    """`sim.sh IMAGE T N` against `stereonav harris IMAGE --threshold T --max-features N`."""

    name: str
    image: bytes  # the file's bytes (usually a PGM)
    threshold: str
    max_features: str
    seed: int = 0  # HDL_SIM_SEED: an irregular pixel stream and link
    same_stderr: bool = False  # the register errors' messages are the same words


@dataclass
class PacketCase:
    """`sim.sh --packet` against `stereonav fpga emulate`, and decoded by `stereonav fpga decode`."""

    name: str
    pairs: list[tuple[Image, Image]]
    threshold: int
    max_features: int
    t0_us: int = 0
    period_us: int = 50_000
    first_frame: int = 0
    seed: int = 0


@dataclass
class Result:
    name: str
    ok: bool
    detail: str = ""
    features: int = 0  # features compared (stereonav harris's lines)


def registers(rng: random.Random) -> tuple[str, str]:
    threshold = rng.choice(
        [I32_MIN, I32_MIN + 1, -(2**20), -1, 0, 1, 1000, 1 << 14, DEFAULT_THRESHOLD, 1 << 22, I32_MAX - 1, I32_MAX]
    )
    return str(threshold), str(rng.choice([1, 2, 7, 100, 512, MAX_FEATURES_LIMIT]))


def fast_cases(rng: random.Random, euroc_left: Image | None) -> list[HarrisCase | PacketCase]:
    cases: list[HarrisCase | PacketCase] = []

    def add(name: str, image: Image | bytes, threshold: int | str, max_features: int | str, **kw) -> None:
        data = image.pgm() if isinstance(image, Image) else image
        cases.append(HarrisCase(name, data, str(threshold), str(max_features), **kw))

    # The integer ranges' edges on small images of every kind.
    edges = [I32_MIN, I32_MIN + 1, -1, 0, 1, DEFAULT_THRESHOLD, I32_MAX - 1, I32_MAX]
    smallest = noise(rng, 16, 16)
    for threshold in edges:
        for max_features in (1, 2, MAX_FEATURES_LIMIT):
            add(f"16x16 noise T={threshold} N={max_features}", smallest, threshold, max_features)
    for width, height in [(16, 17), (17, 16), (16, 40), (40, 16), (23, 19), (31, 33), (64, 48), (97, 35)]:
        for kind in ("noise", "saturated", "plateaus", "smooth"):
            image = {
                "noise": lambda: noise(rng, width, height),
                "saturated": lambda: saturated_noise(rng, width, height),
                "plateaus": lambda: plateaus(rng, width, height),
                "smooth": lambda: smooth(rng, width, height),
            }[kind]()
            threshold, max_features = registers(rng)
            add(f"{width}x{height} {kind} T={threshold} N={max_features}", image, threshold, max_features)
    for period in (1, 2, 3, 5):
        for threshold in (I32_MIN, -1, 0, DEFAULT_THRESHOLD):
            add(f"checkerboard/{period} T={threshold}", checkerboard(37, 29, period), threshold, MAX_FEATURES_LIMIT)
    add("constant image T=i32::MIN", Image(20, 20, bytes([77]) * 400), I32_MIN, 5)
    add("black image T=-1", Image(16, 16, bytes(256)), -1, 5)
    # The largest responses an image gives (8.9e8 < 2^31): saturated noise at every threshold.
    big_responses = saturated_noise(rng, 48, 48)
    for threshold in (1 << 28, 1 << 29, 900_000_000, I32_MAX):
        add(f"saturated 48x48 T={threshold}", big_responses, threshold, MAX_FEATURES_LIMIT)
    # The largest response known (885,997,127: harris-core's tests/integration/extremes.rs, a
    # searched 7x7 binary patch), on either background, just below and at its value.
    patch = [
        [0, 0, 0, 0, 0, 0, 255],
        [0, 255, 255, 0, 0, 255, 255],
        [0, 255, 255, 255, 0, 255, 255],
        [0, 0, 255, 255, 0, 0, 255],
        [0, 0, 0, 0, 0, 0, 255],
        [0, 255, 255, 0, 0, 255, 255],
        [255, 255, 255, 255, 255, 255, 255],
    ]
    for background in (0, 255):
        px = bytearray([background] * 256)
        for dy, row in enumerate(patch):
            px[(5 + dy) * 16 + 5 : (5 + dy) * 16 + 12] = bytes(row)
        for threshold in (0, 885_997_126, 885_997_127):
            add(f"largest response on {background} T={threshold}", Image(16, 16, bytes(px)), threshold, 1023)
    # MAX_FEATURES 1023 and the overflow: noise at i32::MIN has a feature every few pixels.
    many = noise(rng, 120, 110)
    for max_features in (1, 1022, 1023):
        add(f"120x110 noise, overflow at N={max_features}", many, I32_MIN, max_features)
    add("80x80 noise, no overflow at N=1023", noise(rng, 80, 80), I32_MIN, MAX_FEATURES_LIMIT)
    # The widest and tallest images the ICD allows, and their line buffers' last column.
    add("4095x16 noise", noise(rng, 4095, 16), 0, MAX_FEATURES_LIMIT)
    add("16x4095 noise", noise(rng, 16, 4095), 0, MAX_FEATURES_LIMIT)
    add("4095x20 lamps", lamps(rng, 4095, 20, 40), DEFAULT_THRESHOLD, MAX_FEATURES_LIMIT)
    # Lamps at sub-pixel positions (the offsets' rounding), with and without noise.
    for i in range(3):
        add(f"lamps 96x72 #{i}", lamps(rng, 96, 72, 12, noise_dn=0.0 if i == 0 else 2.0), DEFAULT_THRESHOLD, 512)
    add("lamps 96x72 T=0", lamps(rng, 96, 72, 10), 0, 512)
    # Crops of a real frame.
    if euroc_left is not None:
        for x0, y0, w, h in [(0, 0, 96, 64), (300, 200, 128, 96), (752 - 80, 480 - 40, 80, 40)]:
            for threshold in (0, 1 << 14, DEFAULT_THRESHOLD):
                add(f"EuRoC crop {w}x{h}+{x0}+{y0} T={threshold}", euroc_left.crop(x0, y0, w, h), threshold, 512)
    # An irregular pixel stream and link give the same features.
    for seed in (1, 2, 3):
        add(f"irregular stream seed {seed}", noise(rng, 40, 30), 0, 100, seed=seed)
    add("irregular stream, overflow", many, I32_MIN, 600, seed=4)

    # Register errors: refused with the same message and status (stereonav: exit 1).
    for width, height in [(1, 1), (1, 16), (16, 1), (1, 40), (40, 1), (15, 16), (16, 15), (4096, 16), (16, 4096), (0, 16)]:
        add(f"{width}x{height} refused", noise(rng, width, height), 0, 10, same_stderr=True)
    add("one row and one column too small", noise(rng, 15, 3), 0, 10, same_stderr=True)
    for max_features in (0, 1024, 65535, 2**40, 2**64 - 1):
        add(f"N={max_features} refused", smallest, 0, max_features, same_stderr=True)
    add("N=0 and a bad width: the width is reported", noise(rng, 8, 16), 0, 0, same_stderr=True)
    # Malformed numbers: stereonav's command line refuses them (exit 2), so does sim.sh.
    for threshold in ("2147483648", "-2147483649", "abc", "1.5", "", " 5"):
        add(f"THRESHOLD {threshold!r} refused", smallest, threshold, 10)
    for max_features in ("-1", "x", "", str(2**64)):
        add(f"MAX_FEATURES {max_features!r} refused", smallest, 0, max_features)
    add("THRESHOLD +5 and -0 accepted", smallest, "+5", "+3")
    add("THRESHOLD -0 accepted", smallest, "-0", "010")
    # PGM variants stereonav reads, and files it refuses (exit 1).
    scaled = noise(rng, 20, 20, 0, 100)
    add("MAXVAL 100 (scaled)", b"P5\n20 20\n100\n" + scaled.pixels, 0, 100)
    add("MAXVAL 1", b"P5 16 16 1\n" + bytes(rng.randint(0, 1) for _ in range(256)), -1, 100)
    add("header comment", b"P5\n# a comment\n16 16\n255\n" + smallest.pixels, 0, 100)
    add("bytes after the image", smallest.pgm() + b"trailing", 0, 100)
    add("truncated", smallest.pgm()[:-1], 0, 100)
    add("16-bit PGM", b"P5\n16 16\n65535\n" + bytes(512), 0, 100)
    add("MAXVAL 0", b"P5\n16 16\n0\n" + bytes(256), 0, 100)

    # Other images stereonav reads: sim.sh converts them (hdl/sim/to_pgm.py).
    add("8-bit gray PNG", png(30, 20, noise(rng, 30, 20).pixels), 0, 100)
    add("8-bit gray PNG, every row filter", png(30, 20, noise(rng, 30, 20).pixels, filters=bytes(range(5))), 0, 100)
    add("ASCII PGM, MAXVAL 100", b"P2\n# ascii\n20 20\n100\n" + " ".join(str(rng.randint(0, 100)) for _ in range(400)).encode(), 0, 100)
    add("RGB PNG refused", png(16, 16, bytes(768), colour=2), 0, 100, same_stderr=True)
    add("16-bit PNG refused", png(16, 16, bytes(512), depth=16), 0, 100, same_stderr=True)
    add("PNG 1x16 refused", png(1, 16, bytes(16)), 0, 100, same_stderr=True)
    if EUROC.is_dir():
        first_png = sorted((EUROC / "left").glob("*.png"))[0]
        add("a real EuRoC PNG frame, whole", first_png.read_bytes(), DEFAULT_THRESHOLD, 512)

    # Packets: the encoder's byte stream against fpga-link's encoder and decoder.
    left, right = lamps(rng, 64, 48, 8), lamps(rng, 64, 48, 8)
    cases.append(
        PacketCase(
            "packets: lamps, overflow, empty, one-sided, sizes change",
            [
                (left, right),
                (noise(rng, 40, 30), noise(rng, 40, 30)),  # overflow on both at N=20 and T=0
                (Image(20, 20, bytes(400)), Image(20, 20, bytes(400))),  # no features
                (Image(32, 32, bytes(1024)), noise(rng, 32, 32)),  # left empty
                (noise(rng, 32, 32), Image(32, 32, bytes(1024))),  # right empty
            ],
            0,
            20,
            t0_us=1_000_000,
            period_us=16_667,
        )
    )
    cases.append(
        PacketCase(
            "packets: the frame counter wraps, the timestamp saturates, irregular link",
            [(noise(rng, 24, 24), noise(rng, 24, 24)) for _ in range(3)],
            I32_MIN,
            MAX_FEATURES_LIMIT,
            t0_us=2**64 - 20_000,
            period_us=15_000,
            first_frame=2**32 - 2,
            seed=7,
        )
    )
    cases.append(PacketCase("packets: 1023 features a camera", [(many, many)], I32_MIN, MAX_FEATURES_LIMIT))
    return cases


def slow_cases(rng: random.Random, euroc: list[tuple[Image, Image]]) -> list[HarrisCase | PacketCase]:
    cases: list[HarrisCase | PacketCase] = []
    thresholds = [I32_MIN, -1, 0, 1 << 10, 1 << 14, DEFAULT_THRESHOLD, 1 << 20, 1 << 22, 1 << 26, I32_MAX]
    for i, (left, right) in enumerate(euroc):
        for side, image in (("left", left), ("right", right)):
            for threshold in thresholds:
                for max_features in (1, 512, MAX_FEATURES_LIMIT):
                    cases.append(
                        HarrisCase(f"EuRoC {side} #{i} T={threshold} N={max_features}", image.pgm(), str(threshold), str(max_features))
                    )
    if euroc:
        cases.append(PacketCase("packets: the ten EuRoC stereo pairs", euroc, DEFAULT_THRESHOLD, 512))
        cases.append(PacketCase("packets: EuRoC pairs, 1023 features, irregular", euroc[:3], 0, MAX_FEATURES_LIMIT, seed=11))
    fixture = LAMPS_FIXTURE.read_bytes()  # a PNG: sim.sh converts it
    for threshold in thresholds:
        cases.append(HarrisCase(f"ceiling-lamps fixture (PNG) T={threshold}", fixture, str(threshold), "512"))
    for i in range(4):
        image = lamps(rng, 752, 480, 30, noise_dn=3.0)
        for threshold in (0, DEFAULT_THRESHOLD, 1 << 22):
            cases.append(HarrisCase(f"lamps 752x480 #{i} T={threshold}", image.pgm(), str(threshold), "512"))
    for width, height in [(752, 480), (1024, 1024), (4095, 200), (200, 4095)]:
        image = noise(rng, width, height)
        for threshold, max_features in ((I32_MIN, MAX_FEATURES_LIMIT), (1 << 22, 512)):
            cases.append(HarrisCase(f"noise {width}x{height} T={threshold}", image.pgm(), str(threshold), str(max_features)))
    image = saturated_noise(rng, 752, 480)
    for threshold in (1 << 28, 1 << 29, I32_MAX):
        cases.append(HarrisCase(f"saturated 752x480 T={threshold}", image.pgm(), str(threshold), str(MAX_FEATURES_LIMIT)))
    for seed in (21, 22):
        cases.append(HarrisCase(f"irregular stream 752x480 seed {seed}", noise(rng, 752, 480).pgm(), "0", "1023", seed=seed))
    return cases


# --- running ----------------------------------------------------------------------------------


def run(cmd: list[str], env: dict[str, str] | None = None) -> subprocess.CompletedProcess[bytes]:
    return subprocess.run(cmd, capture_output=True, env=env, timeout=900, check=False)


def check_harris(case: HarrisCase, stereonav: str, tmp: Path, index: int) -> Result:
    image = tmp / f"case{index}.pgm"
    image.write_bytes(case.image)
    env = dict(os.environ)
    env.pop("HDL_SIM_SEED", None)
    if case.seed:
        env["HDL_SIM_SEED"] = str(case.seed)
    ref = run([stereonav, "harris", str(image), "--threshold", case.threshold, "--max-features", case.max_features])
    hdl = run(["bash", str(SIM), str(image), case.threshold, case.max_features], env)
    problems = []
    if hdl.returncode != ref.returncode:
        problems.append(f"exit status {hdl.returncode}, stereonav {ref.returncode}")
    if hdl.stdout != ref.stdout:
        problems.append(first_difference(hdl.stdout, ref.stdout))
    if case.same_stderr and hdl.stderr != ref.stderr:
        problems.append(f"stderr {hdl.stderr!r}, stereonav {ref.stderr!r}")
    if ref.returncode == 0 and hdl.stderr.strip():
        problems.append(f"unexpected stderr {hdl.stderr[-300:]!r}")
    detail = "; ".join(problems)
    if problems:
        detail += f" [registers {case.threshold} {case.max_features}; hdl stderr {hdl.stderr[-300:]!r}]"
    features = max(0, len(ref.stdout.splitlines()) - 1) if ref.returncode == 0 else 0
    return Result(case.name, not problems, detail, features)


def first_difference(got: bytes, want: bytes) -> str:
    got_lines, want_lines = got.decode(errors="replace").splitlines(), want.decode(errors="replace").splitlines()
    for i, (a, b) in enumerate(zip(got_lines, want_lines)):
        if a != b:
            return f"line {i + 1}: hdl {a!r}, stereonav {b!r}"
    return f"hdl printed {len(got_lines)} lines, stereonav {len(want_lines)}"


def check_packets(case: PacketCase, stereonav: str, tmp: Path, index: int) -> Result:
    files = []
    for i, (left, right) in enumerate(case.pairs):
        for side, image in (("l", left), ("r", right)):
            path = tmp / f"packet{index}-{i}{side}.pgm"
            path.write_bytes(image.pgm())
            files.append(str(path))
    hdl_bin, ref_bin = tmp / f"packet{index}.hdl.bin", tmp / f"packet{index}.ref.bin"
    env = dict(os.environ)
    env.pop("HDL_SIM_SEED", None)
    if case.seed:
        env["HDL_SIM_SEED"] = str(case.seed)
    regs = [str(case.threshold), str(case.max_features)]
    timing = [str(case.t0_us), str(case.period_us), str(case.first_frame)]
    hdl = run(["bash", str(SIM), "--packet", str(hdl_bin), *regs, *timing, *files], env)
    if hdl.returncode != 0:
        return Result(case.name, False, f"sim.sh --packet failed: {hdl.stderr[-500:]!r}")
    ref = run(
        [stereonav, "fpga", "emulate", str(ref_bin), *files, "--threshold", regs[0], "--max-features", regs[1],
         "--t0-us", timing[0], "--period-us", timing[1], "--first-frame", timing[2]]
    )
    if ref.returncode != 0:
        return Result(case.name, False, f"stereonav fpga emulate failed: {ref.stderr[-500:]!r}")
    problems = []
    hdl_bytes, ref_bytes = hdl_bin.read_bytes(), ref_bin.read_bytes()
    if hdl_bytes != ref_bytes:
        at = next((i for i, (a, b) in enumerate(zip(hdl_bytes, ref_bytes)) if a != b), min(len(hdl_bytes), len(ref_bytes)))
        problems.append(f"byte streams differ at byte {at} (hdl {len(hdl_bytes)} bytes, fpga-link {len(ref_bytes)})")
    decoded = run([stereonav, "fpga", "decode", str(hdl_bin)])
    lines = [json.loads(line) for line in decoded.stdout.decode().splitlines()]
    frames, stats = lines[:-1], lines[-1] if lines else {}
    want_stats = {"packets": len(case.pairs), "corrupt": 0, "lost": 0, "bytes_skipped": 0}
    if stats != want_stats:
        problems.append(f"decoder counters {stats}, expected {want_stats}")
    for i, frame in enumerate(frames):
        want_frame = (case.first_frame + i) % 2**32
        want_t = min(case.t0_us + case.period_us * i, 2**64 - 1)
        if frame["frame"] != want_frame or frame["t_us"] != want_t:
            problems.append(f"frame {i}: counter {frame['frame']} t_us {frame['t_us']}, expected {want_frame} {want_t}")
        for side, path in (("left", files[2 * i]), ("right", files[2 * i + 1])):
            harris = run([stereonav, "harris", path, "--threshold", regs[0], "--max-features", regs[1]])
            want = [[int(v) for v in line.split(",")] for line in harris.stdout.decode().splitlines()[1:]]
            if frame[side] != want:
                problems.append(f"frame {i} {side}: {len(frame[side])} features decoded, harris gives {len(want)}")
            overflow = frame["flags"] >> (0 if side == "left" else 1) & 1
            if overflow and len(want) != case.max_features:
                problems.append(f"frame {i} {side}: overflow flag with {len(want)} features")
    return Result(case.name, not problems, "; ".join(problems), sum(len(f["left"]) + len(f["right"]) for f in frames))


def stereonav_binary(given: str | None) -> str:
    for candidate in (given, os.environ.get("STEREONAV_BIN"), ROOT / "target/ci/stereonav", ROOT / "target/release/stereonav"):
        if candidate and Path(candidate).is_file():
            return str(candidate)
    sys.exit("hdl/test.py: no stereonav binary: build it (cargo build --release -p stereonav-cli) or pass --stereonav")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--slow", action="store_true", help="the slow tier: whole frames")
    parser.add_argument("--stereonav", help="the stereonav binary to compare with")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 2)
    parser.add_argument("-k", dest="select", default="", help="only cases whose name contains this")
    args = parser.parse_args()
    stereonav = stereonav_binary(args.stereonav)

    # Build the simulation once (or say in one line what is missing) before the cases run.
    probe = run(["bash", str(SIM), "--build"])
    if probe.returncode != 0:
        sys.stderr.write(probe.stderr.decode())
        print("hdl/test.py: hdl/sim.sh cannot build the simulation (see above)")
        print("0 passed, 1 failed")
        return 1

    rng = random.Random(0x5EED_40)
    if args.slow:
        euroc = []
        if EUROC.is_dir():
            for left_png in sorted((EUROC / "left").glob("*.png")):
                euroc.append((read_png_gray8(left_png), read_png_gray8(EUROC / "right" / left_png.name)))
        else:
            print(f"hdl/test.py: {EUROC} is absent: the real EuRoC frames are skipped")
        cases = slow_cases(rng, euroc)
    else:
        euroc_left = None
        first = sorted((EUROC / "left").glob("*.png"))[:1] if EUROC.is_dir() else []
        if first:
            euroc_left = read_png_gray8(first[0])
        else:
            print(f"hdl/test.py: {EUROC} is absent: the EuRoC crops are skipped")
        cases = fast_cases(rng, euroc_left)
    cases = [case for case in cases if args.select in case.name]

    passed = failed = features = 0
    with tempfile.TemporaryDirectory(prefix="hdl-test-") as tmp_dir, concurrent.futures.ThreadPoolExecutor(args.jobs) as pool:
        tmp = Path(tmp_dir)
        futures = [
            pool.submit(check_harris if isinstance(case, HarrisCase) else check_packets, case, stereonav, tmp, i)
            for i, case in enumerate(cases)
        ]
        for future in futures:
            result = future.result()
            features += result.features
            if result.ok:
                passed += 1
            else:
                failed += 1
                print(f"FAIL {result.name}: {result.detail}")
    tier = "slow" if args.slow else "fast"
    print(
        f"hdl/test.py ({tier} tier): sim.sh against stereonav harris, fpga emulate and fpga decode, "
        f"{len(cases)} cases, {features} features compared"
    )
    print(f"{passed} passed, {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
