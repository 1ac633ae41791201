"""stereonav's Harris detector against OpenCV, timed in one process on real frames.

Run from the repository root, after ``maturin develop --release -m crates/py/Cargo.toml``::

    .venv/bin/python bench/harris_vs_opencv.py [--repeat N]

On every EuRoC left frame of ``../shared/data/euroc-v101-stereo/left`` (752x480, the board's
sensor size; the script says so and exits 0 when that folder is absent), single-threaded, it
times with ``time.perf_counter``:

- ``stereonav.harris(img)``: the whole board pipeline (gradients, window sums, response,
  threshold, suppression, sub-pixel offsets, packing into the feature array);
- ``stereonav.harris_response(img)``: the response map only (for reference);
- ``cv2.cornerHarris(img, 5, 3, 41/1024)``: OpenCV's response map only;
- ``cv2.goodFeaturesToTrack(img, 512, 0.01, 1, blockSize=5, useHarrisDetector=True,
  k=41/1024)``: OpenCV's response map plus its corner selection.

Each call is timed separately, frames and methods interleaved, and the table gives the median
over all calls (ms per frame) and the ratio OpenCV time / stereonav.harris time. It then checks
the response maps: against the ICD transcribed in NumPy (bit for bit; the ICD, not OpenCV, is
the reference for exactness) and against OpenCV within the float32 tolerance of the tests.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import platform
import statistics
import sys
import time
from typing import Callable, Dict, List

import numpy as np
import numpy.typing as npt

try:
    import cv2
except ImportError as err:  # pragma: no cover - a message instead of a traceback
    sys.exit(f"cannot import cv2 ({err}); install opencv-python-headless")

REPO_ROOT = pathlib.Path(__file__).resolve().parents[1]
FRAMES_DIR = REPO_ROOT.parent / "shared" / "data" / "euroc-v101-stereo" / "left"
# The tests' NumPy transcription of the ICD and their OpenCV tolerance: one definition.
sys.path.insert(0, str(REPO_ROOT / "crates" / "py" / "tests"))

import board_numpy  # noqa: E402

try:
    import stereonav
except ImportError as err:  # pragma: no cover - a message instead of a traceback
    sys.exit(
        f"cannot import stereonav ({err}); build it first: "
        ".venv/bin/maturin develop --release -m crates/py/Cargo.toml"
    )

K = 41 / 1024


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--repeat", type=int, default=30, help="timed calls per frame and method (default 30)"
    )
    args = parser.parse_args()

    paths = sorted(FRAMES_DIR.glob("*.png"))
    if not paths:
        print(f"skipped: no EuRoC frames in {FRAMES_DIR} (the shared data folder is absent)")
        return 0
    frames: List[npt.NDArray[np.uint8]] = []
    for path in paths:
        frame = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if frame is None or frame.dtype != np.uint8 or frame.ndim != 2:
            print(f"error: {path} is not an 8-bit grayscale image", file=sys.stderr)
            return 1
        frames.append(frame.astype(np.uint8, copy=False))

    cv2.setNumThreads(1)
    methods: Dict[str, Callable[[npt.NDArray[np.uint8]], object]] = {
        "stereonav.harris": lambda img: stereonav.harris(img),
        "stereonav.harris_response": lambda img: stereonav.harris_response(img),
        "cv2.cornerHarris": lambda img: cv2.cornerHarris(img, 5, 3, K),
        "cv2.goodFeaturesToTrack": lambda img: cv2.goodFeaturesToTrack(
            img,
            maxCorners=512,
            qualityLevel=0.01,
            minDistance=1,
            blockSize=5,
            useHarrisDetector=True,
            k=K,
        ),
    }
    what = {
        "stereonav.harris": "whole pipeline, features",
        "stereonav.harris_response": "response map only",
        "cv2.cornerHarris": "response map only",
        "cv2.goodFeaturesToTrack": "response + corner selection",
    }

    for frame in frames:  # warm up caches, SIMD dispatch and OpenCV's buffers
        for method in methods.values():
            method(frame)
    times: Dict[str, List[float]] = {name: [] for name in methods}
    for _ in range(args.repeat):
        for frame in frames:
            for name, method in methods.items():
                start = time.perf_counter()
                method(frame)
                times[name].append(time.perf_counter() - start)

    height, width = frames[0].shape
    print(
        f"Harris on {len(frames)} EuRoC frames ({width}x{height}), {args.repeat} calls each, "
        f"one thread (cv2.getNumThreads() = {cv2.getNumThreads()})"
    )
    print(
        f"stereonav {stereonav.__version__}, OpenCV {cv2.__version__}, NumPy {np.__version__}, "
        f"Python {platform.python_version()}, {platform.machine()}, {os.cpu_count()} CPUs"
    )
    print()
    reference = statistics.median(times["stereonav.harris"])
    header = f"{'method':<27} {'computes':<28} {'ms/frame':>9} {'OpenCV/stereonav':>17}"
    print(header)
    print("-" * len(header))
    for name, samples in times.items():
        median = statistics.median(samples)
        ratio = f"{median / reference:.2f}x" if name.startswith("cv2.") else ""
        print(f"{name:<27} {what[name]:<28} {median * 1e3:>9.3f} {ratio:>17}")
    response_ratio = statistics.median(times["cv2.cornerHarris"]) / statistics.median(
        times["stereonav.harris_response"]
    )
    print(
        "response map only: cv2.cornerHarris / stereonav.harris_response = "
        f"{response_ratio:.2f}x (harris computes exact responses only where needed, so the "
        "whole pipeline can be faster than the full map)"
    )
    print("ms/frame: median over all timed calls; ratio > 1 means stereonav.harris is faster.")

    counts = [len(stereonav.harris(frame)) for frame in frames]
    icd_exact = 0
    opencv_agrees = 0
    for frame in frames:
        r = stereonav.harris_response(frame)
        icd_exact += bool(np.array_equal(r, board_numpy.response(frame)))
        bad = board_numpy.opencv_disagreement(
            r, board_numpy.opencv_response(frame), board_numpy.response_scale(frame)
        )
        opencv_agrees += not bad.any()
    print()
    print(f"features per frame (threshold 2^18, max 512): {min(counts)}..{max(counts)}")
    print(
        f"response map bit-exact with the ICD (board-icd.md section 2, NumPy transcription): "
        f"{icd_exact}/{len(frames)} frames"
    )
    print(
        "response map equal to cv2.cornerHarris(img, 5, 3, 41/1024) * 5100^4 / 2^17 up to the "
        f"floor and float32 rounding (tolerance {board_numpy.OPENCV_RELATIVE_TOLERANCE:.3g} x "
        f"(Sxx+Syy)^2/2^17, as in the tests): {opencv_agrees}/{len(frames)} frames"
    )
    print(
        "(bit-exactness is with respect to the ICD's integer arithmetic; OpenCV works in float32 "
        "and can only agree within rounding)"
    )
    return 0 if icd_exact == opencv_agrees == len(frames) else 1


if __name__ == "__main__":
    sys.exit(main())
