"""The board's Harris arithmetic (board-icd.md section 2) transcribed literally in NumPy, and
its relation to OpenCV's ``cornerHarris``: oracles for the tests and for
``bench/harris_vs_opencv.py``. Exact integer arithmetic (int64), written for clarity, not speed.

Images are 2-D ``uint8`` arrays indexed ``[y, x]``; maps have the image's shape.
"""

from __future__ import annotations

from typing import Any, Tuple

import numpy as np
import numpy.typing as npt

#: ``k = K_NUMERATOR / 2**K_SHIFT = 41 / 1024`` (ICD step 3).
K_NUMERATOR = 41
K_SHIFT = 10
#: ``r = Rs >> RESPONSE_SHIFT`` (ICD step 3).
RESPONSE_SHIFT = 27
#: Window sums and responses exist for ``WINDOW_BORDER <= x <= W - 1 - WINDOW_BORDER`` (step 2).
WINDOW_BORDER = 3
#: Candidates lie at least this far from every edge (step 4).
CANDIDATE_BORDER = 4
#: Sub-pixel offsets are in 1/16 pixel, clamped to [-8, 8] (step 6).
SUBPIXEL_SCALE = 16
SUBPIXEL_CLAMP = 8

#: OpenCV's ``k`` for the same response.
OPENCV_K = K_NUMERATOR / 2**K_SHIFT
#: ``cornerHarris(img, 5, 3, k)`` scales Sobel by ``1 / (4 * 5 * 255) = 1/5100`` (ICD section 2),
#: so its response times ``5100**4`` is ``Rs / 2**10``, and times ``5100**4 / 2**17`` it is
#: ``Rs / 2**27``, whose floor is the board's ``r``.
OPENCV_TO_BOARD = 5100.0**4 / 2**17

#: Tolerance of the OpenCV comparison, relative to ``scale = (Sxx + Syy)**2 / 2**17`` (the size
#: of ``T**2 / 2**17`` in the units of ``r``; every term of ``det - k T**2`` is at most
#: ``T**2 / 4``).
#:
#: OpenCV computes in float32 (unit roundoff ``u = 2**-24``): Sobel with the 1/5100 folded into
#: the kernel (error about ``3u`` of the gradient), the squares and the product (``u``), the
#: 5x5 sums (in float64, rounded once to float32: ``u``), then ``a c - b**2 - k (a + c)**2``
#: (about ``1.2u T**2`` of rounding). Propagated to ``det``, the relative errors of ``a``, ``b``,
#: ``c`` of up to about ``8u`` each give ``|error| <~ 11u T**2``. On the ten EuRoC frames the worst
#: pixel needs ``12.2u`` (gradients that cancel inside the Sobel window make the Sobel error a
#: little larger than ``3u`` of the gradient). ``64u`` leaves five times that margin and is still
#: ten times smaller than a wrong ``k``: ``k = 0.04`` instead of ``41/1024`` moves ``r`` by
#: ``3.9e-5 = 655u`` times ``scale``.
OPENCV_RELATIVE_TOLERANCE = 64 * 2.0**-24
#: Absolute slack of the comparison: in flat areas (``T = 0``) OpenCV's running float64 box sums
#: leave residues of about ``1e-25`` in ``r`` units instead of an exact zero.
OPENCV_ABSOLUTE_TOLERANCE = 2.0**-20

Int64Map = npt.NDArray[np.int64]


def _box5(a: Int64Map) -> Int64Map:
    """Sums of ``a`` over every full 5x5 window, via an int64 integral image (exact)."""
    h, w = a.shape
    integral = np.zeros((h + 1, w + 1), np.int64)
    integral[1:, 1:] = a.cumsum(axis=0).cumsum(axis=1)
    return integral[5:, 5:] - integral[:-5, 5:] - integral[5:, :-5] + integral[:-5, :-5]


def window_sums(image: npt.NDArray[np.uint8]) -> Tuple[Int64Map, Int64Map, Int64Map]:
    """ICD steps 1 and 2: ``Sxx, Syy, Sxy`` of every pixel, int64 maps of the image's shape,
    zero outside ``3 <= x <= W - 4``, ``3 <= y <= H - 4``."""
    p = image.astype(np.int64)
    # Step 1, for 1 <= x <= W-2, 1 <= y <= H-2: index [i, j] is pixel (y, x) = (1 + i, 1 + j).
    gx = (p[:-2, 2:] + 2 * p[1:-1, 2:] + p[2:, 2:]) - (p[:-2, :-2] + 2 * p[1:-1, :-2] + p[2:, :-2])
    gy = (p[2:, :-2] + 2 * p[2:, 1:-1] + p[2:, 2:]) - (p[:-2, :-2] + 2 * p[:-2, 1:-1] + p[:-2, 2:])
    sums = []
    for product in (gx * gx, gy * gy, gx * gy):
        full = np.zeros(image.shape, np.int64)
        # Window centres are 2 gradients in: pixel 1 + 2 = 3.
        full[WINDOW_BORDER:-WINDOW_BORDER, WINDOW_BORDER:-WINDOW_BORDER] = _box5(product)
        sums.append(full)
    return sums[0], sums[1], sums[2]


def response(image: npt.NDArray[np.uint8]) -> Int64Map:
    """ICD steps 1 to 3: the response map ``r``, int64, zero where the board computes none."""
    sxx, syy, sxy = window_sums(image)
    trace = sxx + syy
    det = sxx * syy - sxy * sxy
    rs = (det << K_SHIFT) - K_NUMERATOR * trace * trace  # < 2**59 in magnitude
    return rs >> RESPONSE_SHIFT  # NumPy's >> on int64 is arithmetic, a floor


def suppress(
    r: npt.NDArray[Any], threshold: float
) -> Tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """ICD steps 4 and 5: integer positions ``(ys, xs)`` of the features, in raster order."""
    h, w = r.shape
    b = CANDIDATE_BORDER

    def shifted(dy: int, dx: int) -> npt.NDArray[Any]:
        return r[b + dy : h - b + dy, b + dx : w - b + dx]

    centre = shifted(0, 0)
    keep = centre > threshold
    for dy, dx in ((-1, -1), (-1, 0), (-1, 1), (0, -1)):  # ties lose to earlier pixels
        keep &= centre > shifted(dy, dx)
    for dy, dx in ((0, 1), (1, -1), (1, 0), (1, 1)):  # and win against later ones
        keep &= centre >= shifted(dy, dx)
    ys, xs = np.nonzero(keep)  # row-major: raster order
    return ys + b, xs + b


def subpixel_offset(before: Int64Map, at: Int64Map, after: Int64Map) -> Int64Map:
    """ICD step 6: ``(16 num) / den`` truncated toward zero, 0 when ``den == 0``, in [-8, 8]."""
    num = SUBPIXEL_SCALE * (before - after)
    den = 2 * (before - 2 * at + after)
    safe = np.where(den == 0, 1, den)
    quotient = np.abs(num) // np.abs(safe) * np.sign(num) * np.sign(safe)
    return np.where(den == 0, 0, quotient).clip(-SUBPIXEL_CLAMP, SUBPIXEL_CLAMP)


def features(
    image: npt.NDArray[np.uint8], threshold: int, max_features: int
) -> Tuple[npt.NDArray[np.void], bool]:
    """ICD steps 1 to 7: the board's features (``x_q4``, ``y_q4``, ``r`` records in raster
    order, at most ``max_features``) and its overflow flag."""
    r = response(image)
    ys, xs = suppress(r, threshold)
    ox = subpixel_offset(r[ys, xs - 1], r[ys, xs], r[ys, xs + 1])
    oy = subpixel_offset(r[ys - 1, xs], r[ys, xs], r[ys + 1, xs])
    out = np.zeros(len(ys), np.dtype([("x_q4", "<u2"), ("y_q4", "<u2"), ("r", "<i4")]))
    out["x_q4"] = SUBPIXEL_SCALE * xs + ox
    out["y_q4"] = SUBPIXEL_SCALE * ys + oy
    out["r"] = r[ys, xs]
    return out[:max_features], len(out) > max_features


def opencv_response(image: npt.NDArray[np.uint8], k: float = OPENCV_K) -> npt.NDArray[np.float64]:
    """``cv2.cornerHarris(image, blockSize=5, ksize=3, k)`` in the units of the board's ``r``
    (float64; equal to ``r`` up to float32 rounding and the floor inside the border)."""
    import cv2

    harris = cv2.cornerHarris(image, blockSize=5, ksize=3, k=k)
    return harris.astype(np.float64) * OPENCV_TO_BOARD


def response_scale(image: npt.NDArray[np.uint8]) -> npt.NDArray[np.float64]:
    """Per-pixel magnitude ``(Sxx + Syy)**2 / 2**17`` of the terms of ``r`` (exact float64)."""
    sxx, syy, _ = window_sums(image)
    trace = (sxx + syy).astype(np.float64)  # < 2**26, exact
    return trace * trace / 2**17  # < 2**52 before the division: exact


def opencv_disagreement(
    r: npt.NDArray[np.integer], reference: npt.NDArray[np.float64], scale: npt.NDArray[np.float64]
) -> npt.NDArray[np.bool_]:
    """Pixels inside the border ``3 <= x <= W-4``, ``3 <= y <= H-4`` where the board's ``r`` is
    not the floor of the OpenCV-derived ``reference`` within the float32 tolerance, i.e. where
    ``reference - 1 - tol <= r <= reference + tol`` fails, with
    ``tol = OPENCV_RELATIVE_TOLERANCE * scale + OPENCV_ABSOLUTE_TOLERANCE``. Shape ``(H-6, W-6)``.
    """
    inner = (slice(WINDOW_BORDER, -WINDOW_BORDER), slice(WINDOW_BORDER, -WINDOW_BORDER))
    diff = r[inner].astype(np.float64) - reference[inner]
    tol = OPENCV_RELATIVE_TOLERANCE * scale[inner] + OPENCV_ABSOLUTE_TOLERANCE
    return (diff > tol) | (diff < -1.0 - tol)
