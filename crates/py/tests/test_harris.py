"""Tests of stereonav.harris, harris_detect and harris_response: API, errors, layouts, and the
board's arithmetic against the NumPy transcription of the ICD in ``board_numpy.py``."""

from __future__ import annotations

import ast
import doctest
import inspect
import pathlib
from concurrent.futures import ThreadPoolExecutor
from typing import Callable

import numpy as np
import pytest

import board_numpy
import stereonav
from stereonav import _native

PACKAGE_DIR = pathlib.Path(stereonav.__file__).resolve().parent


def blobs_image(
    centres: list[tuple[int, int]], size: int = 3, shape: tuple[int, int] = (96, 128)
) -> np.ndarray:
    """Dark background (20) with bright (230) ``size`` x ``size`` squares whose top-left pixels
    are ``centre - (size - 1) // 2``."""
    image = np.full(shape, 20, np.uint8)
    for x, y in centres:
        top, left = y - (size - 1) // 2, x - (size - 1) // 2
        image[top : top + size, left : left + size] = 230
    return image


@pytest.fixture(scope="module")
def noise() -> np.ndarray:
    """A 70x90 uniform-noise image: hundreds of features, full-range gradients."""
    return np.random.default_rng(20240611).integers(0, 256, (70, 90), dtype=np.uint8)


# --- API: names, dtypes, shapes, order --------------------------------------------------------


def test_feature_dtype_is_the_board_record() -> None:
    assert stereonav.FEATURE_DTYPE == np.dtype([("x_q4", "<u2"), ("y_q4", "<u2"), ("r", "<i4")])
    assert stereonav.FEATURE_DTYPE.itemsize == _native.FEATURE_RECORD_BYTES == 8


def test_defaults_are_the_board_registers() -> None:
    for function in (stereonav.harris, stereonav.harris_detect):
        parameters = inspect.signature(function).parameters
        assert parameters["threshold"].default == 262144 == 2**18
        assert parameters["max_features"].default == 512
    parameters = inspect.signature(stereonav.harris_detect).parameters
    assert parameters["threshold"].kind is inspect.Parameter.KEYWORD_ONLY
    assert parameters["max_features"].kind is inspect.Parameter.KEYWORD_ONLY


def test_harris_returns_a_structured_array(noise: np.ndarray) -> None:
    features = stereonav.harris(noise)
    assert isinstance(features, np.ndarray)
    assert features.dtype == stereonav.FEATURE_DTYPE
    assert features.ndim == 1 and 0 < len(features) <= 512
    assert features.flags.c_contiguous and features.flags.writeable
    # Positional registers work as in the fixed API (vehicle-interfaces.md section 6).
    np.testing.assert_array_equal(stereonav.harris(noise, 2**18, 512), features)


def test_harris_detect_returns_features_and_overflow(noise: np.ndarray) -> None:
    features, overflow = stereonav.harris_detect(noise, threshold=2**18, max_features=1023)
    assert overflow is False
    np.testing.assert_array_equal(features, stereonav.harris(noise, max_features=1023))
    with pytest.raises(TypeError):
        stereonav.harris_detect(noise, 2**18)  # type: ignore[call-arg]


def test_features_are_in_raster_order(noise: np.ndarray) -> None:
    features = stereonav.harris(noise, threshold=0, max_features=1023)
    ys, xs = board_numpy.suppress(stereonav.harris_response(noise), 0)
    assert len(features) == len(ys) > 100
    # Offsets are within half a pixel of the integer position, so that position is recovered.
    assert np.all(np.abs(features["x_q4"].astype(int) - 16 * xs) <= 8)
    assert np.all(np.abs(features["y_q4"].astype(int) - 16 * ys) <= 8)
    order = np.lexsort((xs, ys))
    np.testing.assert_array_equal(order, np.arange(len(ys)))
    np.testing.assert_array_equal(features["r"], stereonav.harris_response(noise)[ys, xs])


def test_no_features_gives_an_empty_array() -> None:
    for value in (0, 255):
        features, overflow = stereonav.harris_detect(np.full((20, 30), value, np.uint8))
        assert features.shape == (0,) and features.dtype == stereonav.FEATURE_DTYPE
        assert overflow is False


def test_response_map_dtype_shape_and_border(noise: np.ndarray) -> None:
    r = stereonav.harris_response(noise)
    assert r.dtype == np.int32 and r.shape == noise.shape and r.flags.c_contiguous
    border = np.ones(noise.shape, bool)
    border[3:-3, 3:-3] = False
    assert not r[border].any()
    assert np.count_nonzero(r[3:-3, 3:-3]) > 0.9 * r[3:-3, 3:-3].size


# --- The board's arithmetic, against the ICD transcribed in NumPy -----------------------------


def extreme_images() -> list[np.ndarray]:
    """Images that drive the sums to their extremes: stripes, a checkerboard, a ramp, steps."""
    y, x = np.mgrid[0:40, 0:48]
    return [
        np.where((x // 2) % 2 == 0, 0, 255).astype(np.uint8),  # |gx| = 1020
        np.where((x + y) % 2 == 0, 0, 255).astype(np.uint8),
        np.where(((x // 2) + (y // 2)) % 2 == 0, 255, 0).astype(np.uint8),
        (x * 5 + y * 3).astype(np.uint8),  # wraps: sharp steps
        np.where(x > y, 255, 0).astype(np.uint8),
    ]


def test_response_map_is_the_icd_bit_for_bit(noise: np.ndarray) -> None:
    for image in [noise, *extreme_images()]:
        expected = board_numpy.response(image)
        assert expected.min() >= -(2**31) and expected.max() < 2**31
        np.testing.assert_array_equal(stereonav.harris_response(image), expected)


@pytest.mark.parametrize(("threshold", "max_features"), [(2**18, 512), (0, 1023), (-5, 7)])
def test_features_are_the_icd_bit_for_bit(
    noise: np.ndarray, threshold: int, max_features: int
) -> None:
    for image in [noise, *extreme_images()]:
        expected, expected_overflow = board_numpy.features(image, threshold, max_features)
        features, overflow = stereonav.harris_detect(
            image, threshold=threshold, max_features=max_features
        )
        np.testing.assert_array_equal(features, expected)
        assert overflow == expected_overflow


# --- Small bright lamps (ICD section 2: one feature at the centre, within about 0.1 px) -------


@pytest.mark.parametrize("size", [3, 5])
def test_each_small_blob_gives_one_feature_at_its_centre(size: int) -> None:
    # (A single bright pixel is not such a lamp: its response is a flat 3x3 plateau, whose
    # raster-order winner is the top-left pixel, reported half a pixel up and left.)
    centres = [(20, 16), (64, 30), (100, 50), (30, 70), (90, 80)]
    features = stereonav.harris(blobs_image(centres, size))
    assert len(features) == len(centres)
    found = sorted(zip(features["x_q4"] / 16, features["y_q4"] / 16))
    for (u, v), (x, y) in zip(found, sorted(centres)):
        assert abs(u - x) <= 0.1 and abs(v - y) <= 0.1, (u, v, x, y)


@pytest.mark.parametrize("size", [2, 4])
def test_even_blobs_give_one_feature_at_the_half_pixel_centre(size: int) -> None:
    corners = [(20, 16), (64, 30), (100, 50), (30, 70)]
    image = np.full((96, 128), 20, np.uint8)
    for x, y in corners:
        image[y : y + size, x : x + size] = 230
    features = stereonav.harris(image)
    assert len(features) == len(corners)
    found = sorted(zip(features["x_q4"] / 16, features["y_q4"] / 16))
    for (u, v), (x, y) in zip(found, sorted(corners)):
        cx, cy = x + (size - 1) / 2, y + (size - 1) / 2
        assert abs(u - cx) <= 0.1 and abs(v - cy) <= 0.1, (u, v, cx, cy)


def test_overflow_flag_keeps_the_first_features_in_raster_order() -> None:
    image = blobs_image([(20, 16), (64, 30), (100, 50), (30, 70)])
    everything, overflow = stereonav.harris_detect(image, max_features=1023)
    assert len(everything) == 4 and overflow is False

    first, overflow = stereonav.harris_detect(image, max_features=1)
    assert overflow is True
    np.testing.assert_array_equal(first, everything[:1])
    assert first["y_q4"][0] == 16 * 16  # the topmost lamp

    exactly, overflow = stereonav.harris_detect(image, max_features=4)
    assert overflow is False  # the flag means *more* than MAX_FEATURES
    np.testing.assert_array_equal(exactly, everything)
    assert len(stereonav.harris(image, max_features=1)) == 1


# --- Memory layouts ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "view",
    [
        lambda a: a[::2, ::3],  # strided
        lambda a: a[5:60, 7:80],  # rows contiguous, not the whole buffer
        lambda a: a[::-1, ::-1],  # negative strides
        lambda a: np.asfortranarray(a),  # column-major
        lambda a: a.T,  # transposed view
        lambda a: np.broadcast_to(a[10], (40, a.shape[1])),  # zero stride, read-only
    ],
    ids=["strided", "cropped", "reversed", "fortran", "transposed", "broadcast"],
)
def test_non_contiguous_views_give_the_same_result_as_a_copy(
    noise: np.ndarray, view: Callable[[np.ndarray], np.ndarray]
) -> None:
    image = view(noise)
    copy = np.ascontiguousarray(image)
    assert copy.flags.c_contiguous
    for threshold in (2**18, 0):
        features, overflow = stereonav.harris_detect(image, threshold=threshold, max_features=1023)
        expected, expected_overflow = stereonav.harris_detect(
            copy, threshold=threshold, max_features=1023
        )
        np.testing.assert_array_equal(features, expected)
        assert overflow == expected_overflow
    np.testing.assert_array_equal(stereonav.harris_response(image), stereonav.harris_response(copy))


def test_read_only_and_big_endian_labelled_inputs_are_accepted(noise: np.ndarray) -> None:
    read_only = noise.copy()
    read_only.flags.writeable = False
    np.testing.assert_array_equal(stereonav.harris(read_only), stereonav.harris(noise))
    np.testing.assert_array_equal(
        stereonav.harris(noise.astype(">u1")), stereonav.harris(noise)
    )


def test_concurrent_calls_from_threads_agree(noise: np.ndarray) -> None:
    expected = stereonav.harris(noise, threshold=0, max_features=1023)
    with ThreadPoolExecutor(max_workers=4) as pool:
        results = list(pool.map(lambda _: stereonav.harris(noise, 0, 1023), range(16)))
    for features in results:
        np.testing.assert_array_equal(features, expected)


# --- Errors -----------------------------------------------------------------------------------


def test_exception_hierarchy() -> None:
    assert issubclass(stereonav.InputError, stereonav.Error)
    assert issubclass(stereonav.InputError, ValueError)
    assert issubclass(stereonav.InputTypeError, stereonav.Error)
    assert issubclass(stereonav.InputTypeError, TypeError)
    assert issubclass(stereonav.Error, Exception)


@pytest.mark.parametrize(
    ("image", "message"),
    [
        ([[0] * 32] * 32, "list"),
        (None, "NoneType"),
        (memoryview(bytes(32 * 32)).cast("B", (32, 32)), "memoryview"),
        (np.zeros((32, 32), np.float64), "float64"),
        (np.zeros((32, 32), np.int8), "int8"),
        (np.zeros((32, 32), np.uint16), "uint16"),
        (np.zeros((32, 32), bool), "bool"),
    ],
)
def test_wrong_image_type_raises_type_error(image: object, message: str) -> None:
    for call in (
        lambda: stereonav.harris(image),  # type: ignore[arg-type]
        lambda: stereonav.harris_detect(image),  # type: ignore[arg-type]
        lambda: stereonav.harris_response(image),  # type: ignore[arg-type]
    ):
        with pytest.raises(stereonav.InputTypeError, match=message):
            call()


@pytest.mark.parametrize(
    ("shape", "message"),
    [
        ((32,), r"shape is \(32,\)"),
        ((32, 32, 3), r"shape is \(32, 32, 3\)"),
        ((1, 32, 32), r"shape is \(1, 32, 32\)"),
        ((), r"shape is \(\)"),
        ((15, 32), r"height 15 \(shape \(15, 32\)\) is outside the board's range 16..=4095"),
        ((32, 15), r"width 15 .* outside"),
        ((0, 32), r"height 0 .* outside"),
        ((16, 4096), r"width 4096 .* outside"),
    ],
)
def test_wrong_image_shape_raises_value_error(shape: tuple[int, ...], message: str) -> None:
    image = np.zeros(shape, np.uint8)
    for call in (
        lambda: stereonav.harris(image),
        lambda: stereonav.harris_response(image),
    ):
        with pytest.raises(stereonav.InputError, match=message):
            call()
        with pytest.raises(ValueError):
            call()


def test_smallest_and_largest_sizes_work() -> None:
    assert len(stereonav.harris(np.zeros((16, 16), np.uint8))) == 0
    assert stereonav.harris_response(np.zeros((16, 4095), np.uint8)).shape == (16, 4095)


@pytest.mark.parametrize("threshold", [1.5, 262144.0, "262144", None, True, False, np.bool_(True)])
def test_threshold_of_wrong_type_raises_type_error(noise: np.ndarray, threshold: object) -> None:
    expected = f"threshold must be an int, got {type(threshold).__qualname__}"
    with pytest.raises(stereonav.InputTypeError, match=expected):
        stereonav.harris(noise, threshold)  # type: ignore[arg-type]


@pytest.mark.parametrize("max_features", [1.0, "512", None, True])
def test_max_features_of_wrong_type_raises_type_error(
    noise: np.ndarray, max_features: object
) -> None:
    with pytest.raises(stereonav.InputTypeError, match="max_features must be an int"):
        stereonav.harris(noise, max_features=max_features)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("threshold", "max_features", "message"),
    [
        (2**31, 512, "threshold 2147483648 is outside"),
        (-(2**31) - 1, 512, "threshold -2147483649 is outside"),
        (2**80, 512, f"threshold {2**80} is outside"),
        (0, 0, "max_features 0 is outside the board's range 1..=1023"),
        (0, 1024, "max_features 1024 is outside"),
        (0, -1, "max_features -1 is outside"),
    ],
)
def test_register_out_of_range_raises_value_error(
    noise: np.ndarray, threshold: int, max_features: int, message: str
) -> None:
    with pytest.raises(stereonav.InputError, match=message):
        stereonav.harris_detect(noise, threshold=threshold, max_features=max_features)


def test_register_limits_and_numpy_integers_are_accepted(noise: np.ndarray) -> None:
    for threshold in (-(2**31), 2**31 - 1, np.int64(2**18), np.uint32(2**18), np.int8(-3)):
        stereonav.harris(noise, threshold)  # type: ignore[arg-type]
    for max_features in (1, 1023, np.int16(5)):
        stereonav.harris(noise, max_features=max_features)  # type: ignore[arg-type]
    np.testing.assert_array_equal(
        stereonav.harris(noise, np.int32(1000), np.uint16(9)),  # type: ignore[arg-type]
        stereonav.harris(noise, 1000, 9),
    )


def test_native_module_maps_detector_errors_to_input_error(noise: np.ndarray) -> None:
    # The checks of the wrapper, skipped: the Rust errors must still arrive as InputError.
    cases: list[tuple[Callable[[], object], str]] = [
        (lambda: _native.harris(np.zeros((8, 32), np.uint8), 0, 512), "image height 8 is outside"),
        (lambda: _native.harris(np.zeros((32, 5000), np.uint8), 0, 512), "width 5000 is outside"),
        (lambda: _native.harris(noise, 2**31, 512), "threshold 2147483648 is outside"),
        (lambda: _native.harris(noise, 0, 0), "max_features 0 is outside the board's range"),
        (lambda: _native.harris(noise, 0, 1024), "max_features 1024 is outside"),
        (lambda: _native.harris(noise, 0, -3), "max_features -3 is outside"),
        (lambda: _native.harris_response(np.zeros((32, 3), np.uint8)), "width 3 is outside"),
    ]
    for call, message in cases:
        with pytest.raises(stereonav.InputError, match=message):
            call()


def test_native_module_refuses_wrong_arrays_with_type_error() -> None:
    for image in (np.zeros((32, 32), np.float32), np.zeros((32, 32, 1), np.uint8), [[0]]):
        with pytest.raises(TypeError):
            _native.harris(image, 0, 512)  # type: ignore[arg-type]
        with pytest.raises(TypeError):
            _native.harris_response(image)  # type: ignore[arg-type]


# --- Packaging: docs, stubs, typing -----------------------------------------------------------


def test_public_names_are_documented() -> None:
    assert stereonav.__doc__
    for name in stereonav.__all__:
        assert hasattr(stereonav, name), name
        value = getattr(stereonav, name)
        if callable(value):
            assert inspect.getdoc(value), name
    for function in (_native.harris, _native.harris_response):
        assert inspect.getdoc(function)
    assert stereonav.__version__ == _native.__version__


def test_docstring_examples_run() -> None:
    failures, attempted = doctest.testmod(stereonav, verbose=False, report=False)
    assert attempted > 0 and failures == 0


def test_native_stubs_match_the_module() -> None:
    stub = ast.parse((PACKAGE_DIR / "_native.pyi").read_text(encoding="utf-8"))
    stub_functions = {
        node.name: [arg.arg for arg in node.args.args]
        for node in stub.body
        if isinstance(node, ast.FunctionDef)
    }
    stub_names = {
        node.target.id
        for node in stub.body
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)
    }
    stub_classes = {node.name for node in stub.body if isinstance(node, ast.ClassDef)}
    native_names = {name for name in dir(_native) if not name.startswith("_")} | {"__version__"}
    assert set(stub_functions) | stub_names | stub_classes == native_names
    for name, parameters in stub_functions.items():
        signature = inspect.signature(getattr(_native, name))
        assert list(signature.parameters) == parameters, name


def test_package_is_marked_typed() -> None:
    assert (PACKAGE_DIR / "py.typed").is_file()
