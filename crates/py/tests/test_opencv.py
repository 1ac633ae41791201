"""stereonav's Harris detector against OpenCV on real frames (board-icd.md section 2, "Float
relation"): ``r`` equals ``cv2.cornerHarris(img, 5, 3, 41/1024) * 5100**4 / 2**17`` up to
float32 rounding and the floor, so the same threshold and suppression give the same corners.

The frames are the ten EuRoC V1_01 left images of ``../shared/data`` next to the repository
(752x480, the board's sensor size); the tests skip where that folder or OpenCV is absent.
"""

from __future__ import annotations

import pathlib

import numpy as np
import pytest

import board_numpy
import stereonav

cv2 = pytest.importorskip("cv2")

REPO_ROOT = pathlib.Path(__file__).resolve().parents[3]
FRAMES_DIR = REPO_ROOT.parent / "shared" / "data" / "euroc-v101-stereo" / "left"


@pytest.fixture(scope="module")
def frames() -> list[np.ndarray]:
    """The EuRoC left frames, 8-bit grayscale, shape (480, 752)."""
    paths = sorted(FRAMES_DIR.glob("*.png"))
    if not paths:
        pytest.skip(f"no EuRoC frames in {FRAMES_DIR} (the shared data folder is absent)")
    images = [cv2.imread(str(path), cv2.IMREAD_UNCHANGED) for path in paths]
    for path, image in zip(paths, images):
        assert image is not None and image.dtype == np.uint8 and image.shape == (480, 752), path
    return images


def test_response_is_the_icd_bit_for_bit(frames: list[np.ndarray]) -> None:
    for image in frames:
        np.testing.assert_array_equal(
            stereonav.harris_response(image), board_numpy.response(image)
        )


def test_response_equals_opencv_up_to_float32_rounding_and_the_floor(
    frames: list[np.ndarray],
) -> None:
    # board_numpy.OPENCV_RELATIVE_TOLERANCE explains the bound: 64 float32 roundoffs of
    # (Sxx + Syy)**2 / 2**17, five times the worst pixel seen, and one-sided, so that a
    # rounded instead of floored r, a wrong k or a shifted window would all fail.
    for image in frames:
        r = stereonav.harris_response(image)
        scale = board_numpy.response_scale(image)
        bad = board_numpy.opencv_disagreement(r, board_numpy.opencv_response(image), scale)
        assert not bad.any(), f"{np.count_nonzero(bad)} pixels differ beyond float32 rounding"
        # The comparison is not vacuous: the responses span many orders of magnitude.
        assert scale.max() > 1e8 and np.abs(r).max() > 1e7


def test_the_opencv_tolerance_rejects_a_wrong_k(frames: list[np.ndarray]) -> None:
    image = frames[0]
    r = stereonav.harris_response(image)
    scale = board_numpy.response_scale(image)
    wrong_k = board_numpy.opencv_disagreement(r, board_numpy.opencv_response(image, k=0.04), scale)
    assert wrong_k.mean() > 0.1  # k = 0.04 instead of 41/1024 = 0.0400390625
    shifted = np.roll(board_numpy.opencv_response(image), 1, axis=1)
    assert board_numpy.opencv_disagreement(r, shifted, scale).mean() > 0.5


def test_features_equal_opencv_corners_with_the_same_threshold_and_suppression(
    frames: list[np.ndarray],
) -> None:
    threshold = stereonav.DEFAULT_THRESHOLD
    for image in frames:
        features, overflow = stereonav.harris_detect(
            image, threshold=threshold, max_features=stereonav.MAX_FEATURES_LIMIT
        )
        assert not overflow and len(features) > 100
        # The board compares integers; flooring OpenCV's response gives it the same ties.
        reference = np.floor(board_numpy.opencv_response(image))
        ys, xs = board_numpy.suppress(reference, threshold)
        opencv_corners = set(zip(ys.tolist(), xs.tolist()))
        # A feature's integer pixel is within half a pixel (8 sixteenths) of x_q4, y_q4.
        x_q4 = features["x_q4"].astype(int)
        y_q4 = features["y_q4"].astype(int)
        matched = 0
        for x, y in zip(x_q4.tolist(), y_q4.tolist()):
            near = {
                (row, col)
                for row in ((y - 8 + 15) // 16, (y + 8) // 16)
                for col in ((x - 8 + 15) // 16, (x + 8) // 16)
            }
            matched += bool(near & opencv_corners)
        # Float32 rounding may flip near-ties, so ask for 99%, both ways.
        assert matched >= 0.99 * max(len(features), len(opencv_corners)), (
            matched,
            len(features),
            len(opencv_corners),
        )
