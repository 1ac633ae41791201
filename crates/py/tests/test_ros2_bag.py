"""Robot logs with camera images: ROS 2 bags (``vehicle-interfaces.md`` 4.1) from Python.

Bags are written by two independent writers (``ros2_writers``: mcap-ros2-support's
``mcap_ros2.writer.Writer`` with the standard message definitions written out, and
``rosbags.rosbag2.Writer``, version 9, MCAP storage, with its built-in definitions) and read
by the stack (``stereonav.read_bag``, ``stereonav.replay``, ``stereonav replay``):

- EuRoC V1_01's ten real stereo pairs (``../shared/data``; skipped without them), as raw
  ``mono8``, as ``rgb8`` and ``bgr8`` (a colour image whose gray by OpenCV's ``cvtColor`` is
  the original exactly), as PNG and as JPEG: the host board's features of every image are
  ``stereonav.harris`` of its gray pixels (for JPEG, of the host's decode, compared with
  ``cv2.imdecode``); rectified through the rig's lenses, left-right matches agree in row.
- Imperfections are counted, never a crash: images of the wrong size, unsupported encodings
  and formats, bytes that do not decode, a frame with one image, stamps within and beyond a
  quarter of the frame interval; ``read_bag``, ``stereonav.replay`` and the command line count
  them alike, and the command line and Python give the same ``SUMMARY.json``.
- A missing topic or one of another type is a one-line error (the command line exits
  non-zero, Python raises ``stereonav.InputError``); arguments of the wrong type raise
  ``TypeError``.
- The odometry decoded by the stack equals mcap_ros2's decoding of the same bag, for both
  writers and for a third party's real bag (``nav2_turtlebot.mcap``, evo's test data).
- ``localize`` and ``fleet.replay_logs`` take the topics as ``replay`` does.
- End to end (slow tier; skipped while ``stereonav simulate`` has no ``--ros2``): the
  simulated radtan experiment as a JPEG bag, and that bag rewritten by each Python writer,
  replay with their topics named to the same summary, Python and the command line alike, the
  lamps and the baseline found against the simulator's truth.
"""

from __future__ import annotations

import functools
import json
import math
import pathlib
import subprocess
from collections.abc import Sequence
from typing import Any, Callable, Optional

import numpy as np
import numpy.typing as npt
import pytest

import stereonav

cv2 = pytest.importorskip("cv2")
pytest.importorskip("mcap_ros2")
pytest.importorskip("rosbags")

import ros2_writers as bags  # noqa: E402  (after the skips: it needs the writers)
from ros2_writers import Compressed, Raw  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[3]
SHARED = ROOT.parent / "shared" / "data"
EUROC = SHARED / "euroc-v101-stereo"
TURTLEBOT = SHARED / "foreign-mcap" / "nav2_turtlebot.mcap"
SCENARIOS = ROOT / "fixtures" / "scenarios"
#: A rig without lenses, 752 x 480, the board's default registers.
PLAIN_RIG = SCENARIOS / "paper-experiment.rig.toml"

LEFT, RIGHT, ODOM = "/cam0/image_raw", "/cam1/image_raw", "/odom"
TOPICS = {"left": LEFT, "right": RIGHT, "odom": ODOM}
CLEFT, CRIGHT = LEFT + "/compressed", RIGHT + "/compressed"
CTOPICS = {"left": CLEFT, "right": CRIGHT, "odom": ODOM}
WRITERS = sorted(bags.WRITERS)
WIDTH, HEIGHT = 752, 480
Gray = npt.NDArray[np.uint8]


def counts(**nonzero: int) -> dict[str, int]:
    """The image counts of :class:`stereonav.ImageCounts`, zero but for ``nonzero``."""
    names = ("left", "right", "frames", "unpaired", "wrong_size", "unsupported", "undecodable",
             "frames_dropped")
    return {name: nonzero.get(name, 0) for name in names}


def counts_of(images: Optional[stereonav.ImageCounts]) -> dict[str, int]:
    assert images is not None
    return {name: getattr(images, name) for name in counts()}


#: ``SUMMARY.json``'s names of the image counts (``frames`` at the top, the others in
#: ``counts``).
SUMMARY_NAMES = {
    "left": "images_left", "right": "images_right", "frames": "frames",
    "unpaired": "images_unpaired", "wrong_size": "images_wrong_size",
    "unsupported": "images_unsupported", "undecodable": "images_undecodable",
    "frames_dropped": "image_frames_dropped",
}


def summary_counts(summary: dict[str, Any]) -> dict[str, int]:
    return {name: summary[key] if key == "frames" else summary["counts"][key]
            for name, key in SUMMARY_NAMES.items()}


def one_line(message: str) -> None:
    assert message and "\n" not in message.strip(), message


# --- The command line ----------------------------------------------------------------------------


def run_cli(cli: pathlib.Path, *args: object, ok: bool = True) -> subprocess.CompletedProcess[str]:
    done = subprocess.run([str(cli), *map(str, args)], capture_output=True, text=True, timeout=600,
                          check=False)
    if ok:
        assert done.returncode == 0, f"stereonav {' '.join(map(str, args))}: {done.stderr}"
    return done


def topic_args(topics: dict[str, str]) -> list[str]:
    return [arg for name, topic in topics.items() for arg in (f"--{name}", topic)]


def cli_summary(cli: pathlib.Path, command: str, log: pathlib.Path, *args: object) -> dict[str, Any]:
    out = log.with_name(f"{log.stem}-{command}-summary.json")
    run_cli(cli, command, log, *args, "--summary", out)
    result: dict[str, Any] = json.loads(out.read_text())
    return result


def assert_same_summary(python: dict[str, Any], command_line: dict[str, Any]) -> None:
    """Key for key and number for number (NaN equal to NaN), as in ``test_parity``."""

    def same(a: Any, b: Any, at: str) -> None:
        if isinstance(a, dict) and isinstance(b, dict):
            assert set(a) == set(b), at
            for key in a:
                same(a[key], b[key], f"{at}.{key}")
        elif isinstance(a, list) and isinstance(b, list):
            assert len(a) == len(b), at
            for i, (x, y) in enumerate(zip(a, b)):
                same(x, y, f"{at}[{i}]")
        elif isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
            pass
        else:
            assert a == b and type(a) is type(b), f"{at}: {a!r} (Python) != {b!r} (command line)"

    same(python, command_line, "summary")


# --- Images ----------------------------------------------------------------------------------------


def colour_of(gray: Gray, seed: int) -> npt.NDArray[np.uint8]:
    """An RGB image, far from gray, whose ``cv2.cvtColor(..., COLOR_RGB2GRAY)`` is ``gray``
    exactly: red and blue pushed apart by a random amount, green solved for the weights
    (``(4899 R + 9617 G + 1868 B + 8192) >> 14``); a pixel where no green fits stays gray."""
    rng = np.random.default_rng(seed)
    g = gray.astype(np.int64)
    offset = rng.integers(-60, 61, size=gray.shape)
    red = np.clip(g + offset, 0, 255)
    blue = np.clip(g - offset, 0, 255)
    green = np.clip(np.round((g * 16384 - 4899 * red - 1868 * blue) / 9617), 0, 255).astype(np.int64)
    fits = ((4899 * red + 9617 * green + 1868 * blue + 8192) >> 14) == g
    rgb = np.where(fits[..., None], np.stack([red, green, blue], axis=-1), g[..., None])
    return rgb.astype(np.uint8)


def encode(gray: Gray, encoding: str, seed: int) -> tuple[Raw | Compressed, Gray]:
    """``gray`` as a message of ``encoding`` and the gray image the host should see in it."""
    if encoding == "mono8":
        return Raw.of(gray, "mono8"), gray
    if encoding in ("rgb8", "bgr8"):
        rgb = colour_of(gray, seed)
        assert np.array_equal(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY), gray)
        assert np.abs(rgb.astype(int) - gray[..., None]).mean() > 10  # colour, not gray
        pixels = rgb if encoding == "rgb8" else rgb[..., ::-1]
        return Raw.of(pixels, encoding), gray
    if encoding == "png":
        ok, png = cv2.imencode(".png", gray)
        assert ok
        return Compressed(png.tobytes(), "png"), gray
    ok, jpeg = cv2.imencode(".jpg", gray, [cv2.IMWRITE_JPEG_QUALITY, 90])
    assert ok
    data = jpeg.tobytes()
    return Compressed(data, "jpeg"), stereonav.decode_image(data)


def lamps(seed: int, shift: int = 0) -> Gray:
    """A synthetic ceiling: a dark 752 x 480 image with a dozen bright discs, shifted left by
    ``shift`` pixels (the right camera's view of far lamps)."""
    rng = np.random.default_rng(seed)
    image = np.full((HEIGHT, WIDTH), 20, np.uint8)
    for x, y in zip(rng.integers(60, WIDTH - 60, 12), rng.integers(30, HEIGHT - 30, 12)):
        cv2.circle(image, (int(x) - shift, int(y)), 4, 230, -1)
    return image


# --- EuRoC's real stereo pairs ---------------------------------------------------------------------


@functools.lru_cache(maxsize=None)
def euroc_pairs() -> tuple[tuple[int, Gray, Gray], ...]:
    """``(t_us, left, right)`` of the ten pairs, in time order."""
    if not (EUROC / "left").is_dir():
        pytest.skip(f"no EuRoC stereo pairs in {EUROC} (the shared data folder is absent)")
    pairs = []
    for path in sorted((EUROC / "left").glob("*.png")):
        left = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        right = cv2.imread(str(EUROC / "right" / path.name), cv2.IMREAD_UNCHANGED)
        assert left.shape == right.shape == (HEIGHT, WIDTH) and left.dtype == np.uint8
        pairs.append((int(path.stem) // 1000, left, right))
    assert len(pairs) == 10
    return tuple(pairs)


@pytest.fixture(scope="module")
def scratch(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    return tmp_path_factory.mktemp("ros2")


@pytest.fixture(scope="module")
def euroc_rig(scratch: pathlib.Path) -> pathlib.Path:
    """EuRoC's calibration as a rig with ``[lens.*]`` (``stereonav.import_rig``, as
    ``test_rig_import`` makes it from the dataset's ``sensor.yaml``)."""
    from test_rig_import import euroc, write_kalibr

    rig = stereonav.import_rig(kalibr=write_kalibr(euroc(), scratch / "camchain.yaml"))
    path = scratch / "euroc.rig.toml"
    path.write_text(rig.to_toml())
    return path


def odometry_rows(t0_us: int, t1_us: int, seed: int) -> npt.NDArray[np.float64]:
    """100 Hz odometry ``(t_us, vx, vy, vtheta)`` over ``t0..t1``, values with every bit
    set somewhere (random doubles, negative ones, zero and a subnormal)."""
    rng = np.random.default_rng(seed)
    t = np.arange(t0_us, t1_us + 1, 10_000)
    rows = np.column_stack([t, rng.normal(0.0, 0.3, len(t)), rng.normal(0.0, 0.05, len(t)),
                            rng.normal(0.0, 0.2, len(t))])
    rows[0, 1:] = [0.0, -0.0, 5e-324]
    return rows


def write_bag(writer: str, directory: pathlib.Path, stem: str,
              frames: Sequence[tuple[int, Optional[tuple[int, Raw | Compressed]],
                                     Optional[tuple[int, Raw | Compressed]]]],
              odometry: npt.NDArray[np.float64], left: str = LEFT, right: str = RIGHT,
              extra: tuple[tuple[str, int, Raw | Compressed], ...] = ()) -> pathlib.Path:
    """A bag of ``frames`` (each ``(t_us, (left stamp, image) or None, (right stamp, image)
    or None)``), ``odometry`` rows and ``extra`` images ``(topic, stamp, image)``, every
    message in stamp order as a recorder writes."""
    messages: list[tuple[int, int, Callable[[Any], None]]] = [
        (t, 3, lambda b, e=(topic, t, image): b.image(*e)) for topic, t, image in extra
    ]
    for _, l, r in frames:
        if l is not None:
            messages.append((l[0], 0, lambda b, l=l: b.image(left, l[0], l[1])))
        if r is not None:
            messages.append((r[0], 1, lambda b, r=r: b.image(right, r[0], r[1])))
    for row in odometry:
        t = int(row[0])
        messages.append((t, 2, lambda b, t=t, row=row: b.odom(ODOM, t, float(row[1]), float(row[2]),
                                                              float(row[3]))))
    out = bags.writer(writer, directory, stem)
    for _, _, write in sorted(messages, key=lambda m: (m[0], m[1])):
        write(out)
    return out.close()


ENCODINGS = ["mono8", "rgb8", "bgr8", "png", "jpeg"]
#: What JPEG decoders disagree on, per image, when the host's decode is compared with
#: OpenCV's (``pytest -s`` prints it).
JPEG_MEASURED: dict[str, list[tuple[int, int, int, int]]] = {}


@pytest.mark.parametrize("encoding", ENCODINGS)
@pytest.mark.parametrize("writer", WRITERS)
def test_euroc_images_give_the_boards_features(
    writer: str, encoding: str, scratch: pathlib.Path, euroc_rig: pathlib.Path
) -> None:
    pairs = euroc_pairs()
    frames, expected = [], []
    for k, (t_us, left, right) in enumerate(pairs):
        lp, lg = encode(left, encoding, 2 * k)
        rp, rg = encode(right, encoding, 2 * k + 1)
        frames.append((t_us, (t_us, lp), (t_us, rp)))
        expected.append((t_us, lg, rg, lp, rp))
    odometry = odometry_rows(pairs[0][0] - 20_000, pairs[-1][0] + 20_000, seed=len(encoding))
    path = write_bag(writer, scratch, f"euroc-{encoding}-{writer}", frames, odometry)

    bag = stereonav.read_bag(path, euroc_rig, **TOPICS)
    assert counts_of(bag.images) == counts(left=10, right=10, frames=10)
    assert bag.images is not None and bag.images.problems == []
    kind = "sensor_msgs/msg/Image" if encoding in ("mono8", "rgb8", "bgr8") else "sensor_msgs/msg/CompressedImage"
    assert bag.topics == {"left": (LEFT, kind), "right": (RIGHT, kind), "odom": (ODOM, "nav_msgs/msg/Odometry")}
    assert bag.messages == {"left": 10, "right": 10, "odom": len(odometry)}
    assert bag.warnings == () and bag.truncated is None and not bag.damage.damaged
    assert [f.t_us for f in bag.frames] == [t for t, *_ in expected]
    for frame, (_, lg, rg, lp, rp) in zip(bag.frames, expected):
        np.testing.assert_array_equal(frame.left, stereonav.harris(lg))
        np.testing.assert_array_equal(frame.right, stereonav.harris(rg))
        assert frame.left.dtype == stereonav.FEATURE_DTYPE and len(frame.left) > 300
        assert not frame.overflow
        if encoding == "jpeg":
            record_jpeg_difference(f"{writer}", lp, lg)
            record_jpeg_difference(f"{writer}", rp, rg)

    # The odometry: as written, and as mcap_ros2's own decoder reads it from the file.
    theirs = bags.read_odometry(path, ODOM)
    ours = np.column_stack([bag.odometry[f] for f in ("t_us", "vx", "vy", "vtheta")])
    np.testing.assert_array_equal(ours, theirs)
    np.testing.assert_array_equal(ours, odometry)
    assert np.signbit(bag.odometry["vy"][0]) and bag.odometry["vtheta"][0] == 5e-324


def record_jpeg_difference(key: str, payload: Raw | Compressed, host: Gray) -> None:
    """The host's decode against ``cv2.imdecode`` of the same bytes: pixels that differ, the
    largest difference, and features whose position differs (of how many)."""
    assert isinstance(payload, Compressed)
    opencv = cv2.imdecode(np.frombuffer(payload.data, np.uint8), cv2.IMREAD_UNCHANGED)
    assert opencv.shape == host.shape
    ours, theirs = stereonav.harris(host), stereonav.harris(opencv)
    at = lambda f: set(zip(f["x_q4"].tolist(), f["y_q4"].tolist()))  # noqa: E731
    moved = len(at(ours) ^ at(theirs))
    pixels = int((host != opencv).sum())
    largest = int(np.abs(host.astype(int) - opencv).max())
    JPEG_MEASURED.setdefault(key, []).append((pixels, largest, moved, len(ours)))
    # Decoders may round the inverse DCT differently (the standard allows it): one grey level
    # on well under 2 % of the pixels of these images (measured: 0.5 %), never more.
    assert largest <= 1 and pixels < 0.02 * host.size, (pixels, largest)
    print(f"JPEG {key}: {pixels} pixels differ (largest {largest}), {moved} feature positions "
          f"of {len(ours)} differ (host decode vs cv2.imdecode)")


#: The rows of matched left and right features, rectified: the median |vL - vR| allowed, px.
#: EuRoC's calibration rectifies to about 0.1 px and the board's sub-pixel step is 1/16 px;
#: measured 0.18 px over the ten pairs. Matches by chance (right rows moved by the raw
#: images' own row offset, 7.3 px, and by 20 px) or on the raw, unrectified rows give 0.9 to
#: 1.3 px, so the bound separates rectified rows from any others.
ROW_MEDIAN_PX = 0.5


def row_differences(left: npt.NDArray[Any], right: npt.NDArray[Any], rig: pathlib.Path,
                    rectify: bool, shift: float = 0.0) -> npt.NDArray[np.float64]:
    """|vL - vR| of each left feature's match: the right feature nearest in row among those
    at a positive disparity below 120 px (EuRoC's nearest scene is about 0.4 m away)."""
    pl = np.column_stack([left["x_q4"], left["y_q4"]]) / 16.0
    pr = np.column_stack([right["x_q4"], right["y_q4"]]) / 16.0
    if rectify:
        pl = stereonav.rectify_points(pl, rig, camera="left")
        pr = stereonav.rectify_points(pr, rig, camera="right")
    pr = pr + [0.0, shift]
    disparity = pl[:, :1] - pr[:, 0][None, :]
    candidate = (disparity > 0) & (disparity < 120)
    dv = np.where(candidate, np.abs(pl[:, 1:2] - pr[:, 1][None, :]), np.inf).min(axis=1)
    return dv[np.isfinite(dv)]


def test_euroc_rectified_rows_of_matches_agree(scratch: pathlib.Path, euroc_rig: pathlib.Path) -> None:
    frames = [(t, (t, Raw.of(l, "mono8")), (t, Raw.of(r, "mono8"))) for t, l, r in euroc_pairs()]
    path = write_bag("mcap_ros2", scratch, "euroc-rows", frames, odometry_rows(frames[0][0], frames[-1][0], 0))
    bag = stereonav.read_bag(path, euroc_rig, **TOPICS)
    assert len(bag.frames) == 10

    def median(**kw: Any) -> float:
        return float(np.median(np.concatenate([row_differences(f.left, f.right, euroc_rig, **kw)
                                               for f in bag.frames])))

    rectified = median(rectify=True)
    controls = {"raw rows": median(rectify=False), "shifted 7.3 px": median(rectify=True, shift=7.3),
                "shifted 20 px": median(rectify=True, shift=20.0)}
    print(f"median |vL - vR|: rectified {rectified:.3f} px; controls {controls}")
    assert rectified < ROW_MEDIAN_PX, rectified
    assert min(controls.values()) > 1.5 * ROW_MEDIAN_PX, controls


# --- Imperfections -------------------------------------------------------------------------------

T0_US, INTERVAL_US, FRAMES = 1_000_000, 50_000, 20
#: An image topic of the imperfect bags that no test names as a camera.
THIRD = "/cam2/image_raw"


def raw_imperfections(seed: int) -> tuple[list[Any], dict[str, int], dict[int, tuple[Gray, Gray]]]:
    """Twenty frames at 20 Hz of raw images, some imperfect. Returns the frames, the image
    counts the host must give and the gray images of the frames it must detect."""
    frames: list[Any] = []
    good: dict[int, tuple[Gray, Gray]] = {}
    for k in range(FRAMES):
        t = T0_US + k * INTERVAL_US
        left, right = lamps(seed + k), lamps(seed + k, shift=20)
        l: Optional[tuple[int, Raw | Compressed]] = (t, Raw.of(left, "mono8"))
        r: Optional[tuple[int, Raw | Compressed]] = (t, Raw.of(right, "mono8"))
        if k == 3:    # the right image of another size
            r = (t, Raw.of(right[:, :640], "mono8"))
        elif k == 5:  # a 16-bit left image
            r16 = left.astype(np.uint16) * 256
            l = (t, Raw.of(r16, "mono16"))
        elif k == 7:  # YUV 4:2:2 on the right
            r = (t, Raw(bytes(2 * WIDTH * HEIGHT), WIDTH, HEIGHT, "yuv422", 2 * WIDTH))
        elif k == 9:  # the right image dropped
            r = None
        elif k == 11:  # the right 10 ms late: within a quarter of the 50 ms interval, a frame
            r = (t + 10_000, r[1])
        elif k == 13:  # 20 ms late: beyond; both alone
            r = (t + 20_000, r[1])
        elif k == 15:  # rows padded to 760 bytes: read by the step
            padded = np.zeros((HEIGHT, 760), np.uint8)
            padded[:, :WIDTH] = left
            l = (t, Raw(padded.tobytes(), WIDTH, HEIGHT, "mono8", 760))
        elif k == 16:  # colour, bgr8, in the mono topic
            l = (t, Raw.of(cv2.cvtColor(left, cv2.COLOR_GRAY2BGR), "bgr8"))
        elif k == 17:  # rows missing: the message holds less than step x height
            l = (t, Raw(left.tobytes()[: WIDTH * 100], WIDTH, HEIGHT, "mono8", WIDTH))
        frames.append((t, l, r))
        if k not in (3, 5, 7, 9, 13, 17):
            good[t] = (left, right)
    expected = counts(left=20, right=19, frames=14, unpaired=3, wrong_size=1, unsupported=2,
                      undecodable=1, frames_dropped=4)
    return frames, expected, good


def garbled_jpeg(image: Gray) -> bytes:
    """A JPEG of ``image`` whose entropy-coded data (after the start of scan) is replaced by
    garbage, its markers intact."""
    data = bytearray(cv2.imencode(".jpg", image)[1].tobytes())
    start = data.index(b"\xff\xda") + 20
    data[start:-2] = bytes((i * 37 + 11) % 251 for i in range(len(data) - 2 - start))
    return bytes(data)


def compressed_imperfections(seed: int) -> tuple[list[Any], dict[str, int], dict[int, tuple[Gray, Gray]]]:
    """Twenty frames of PNG and JPEG images, some imperfect (as :func:`raw_imperfections`)."""
    frames: list[Any] = []
    good: dict[int, tuple[Gray, Gray]] = {}

    def png(image: npt.NDArray[Any]) -> Compressed:
        return Compressed(cv2.imencode(".png", image)[1].tobytes(), "png")

    for k in range(FRAMES):
        t = T0_US + k * INTERVAL_US
        left, right = lamps(seed + k), lamps(seed + k, shift=20)
        l: Compressed = png(left)
        r: Compressed = png(right)
        host_left = left
        if k % 2:  # JPEG on odd frames (a topic's format may change from message to message)
            l = Compressed(cv2.imencode(".jpg", left)[1].tobytes(), "jpeg")
            host_left = stereonav.decode_image(l.data)
        if k == 2:    # a PNG cut short
            r = Compressed(png(right).data[:-100], "png")
        elif k == 4:  # a BMP: a format the host does not read
            r = Compressed(cv2.imencode(".bmp", right)[1].tobytes(), "bmp")
        elif k == 6:  # bytes that are no image
            r = Compressed(b"\x00garbage" * 100, "jpeg")
        elif k == 8:  # a 16-bit PNG
            r = png(right.astype(np.uint16) * 257)
        elif k == 10:  # a PNG of another size
            r = png(right[:400])
        elif k == 12:  # a JPEG whose entropy-coded data is garbage: it decodes (to noise),
            # here as with OpenCV's decoder (libjpeg warns "Corrupt JPEG data" and goes on)
            r = Compressed(garbled_jpeg(right), "jpeg")
            right = stereonav.decode_image(r.data)
        frames.append((t, (t, l), (t, r)))
        if k not in (2, 4, 6, 8, 10):
            good[t] = (host_left, right)
    return frames, {}, good


@functools.lru_cache(maxsize=None)
def imperfect_bag(writer: str, kind: str, directory: pathlib.Path) -> tuple[pathlib.Path, dict[str, int], dict[int, tuple[Gray, Gray]]]:
    make = raw_imperfections if kind == "raw" else compressed_imperfections
    frames, expected, good = make(seed=100)
    odometry = odometry_rows(T0_US - 100_000, T0_US + FRAMES * INTERVAL_US, seed=7)
    odometry[:, 1:] *= 0.1
    left, right = (LEFT, RIGHT) if kind == "raw" else (CLEFT, CRIGHT)
    # A third camera the stack is not asked to read.
    extra = ((THIRD, T0_US, Raw.of(lamps(0), "mono8")),)
    path = write_bag(writer, directory, f"imperfect-{kind}-{writer}", frames, odometry, left, right, extra)
    return path, expected, good


@pytest.mark.parametrize("writer", WRITERS)
def test_imperfect_raw_images_are_counted_alike_by_every_reader(
    writer: str, scratch: pathlib.Path, cli: pathlib.Path
) -> None:
    path, expected, good = imperfect_bag(writer, "raw", scratch)
    bag = stereonav.read_bag(path, PLAIN_RIG, **TOPICS)
    assert counts_of(bag.images) == expected
    assert bag.images is not None
    problems = "\n".join(bag.images.problems)
    assert "640x480 pixels, not the rig's 752x480" in problems, problems
    assert '"mono16"' in problems and "needs" in problems, problems
    # The frames it detected are the good ones, each the board's features of its images.
    assert sorted(good) == [f.t_us for f in bag.frames]
    for frame in bag.frames:
        left, right = good[frame.t_us]
        np.testing.assert_array_equal(frame.left, stereonav.harris(left))
        np.testing.assert_array_equal(frame.right, stereonav.harris(right))
        assert len(frame.left) >= 10

    replayed = stereonav.replay(path, PLAIN_RIG, **TOPICS)
    python = replayed.summary
    assert summary_counts(python) == expected
    # The replay's navigator was given exactly these frames.
    assert replayed.trajectory["t_us"].tolist() == [f.t_us for f in bag.frames]
    assert python["frames"] == 14
    assert any("could not be read" in w for w in python["warnings"]), python["warnings"]
    assert any("no partner" in w for w in python["warnings"]), python["warnings"]
    command_line = cli_summary(cli, "replay", path, "--rig", PLAIN_RIG, *topic_args(TOPICS))
    assert_same_summary(python, command_line)


@pytest.mark.parametrize("writer", WRITERS)
def test_imperfect_compressed_images_are_counted_alike_by_every_reader(
    writer: str, scratch: pathlib.Path, cli: pathlib.Path
) -> None:
    path, _, good = imperfect_bag(writer, "compressed", scratch)
    bag = stereonav.read_bag(path, PLAIN_RIG, **CTOPICS)
    assert bag.images is not None
    measured = counts_of(bag.images)
    print(f"compressed imperfections ({writer}): {measured}; {bag.images.problems}")
    # Frames 2 and 6 do not decode (a cut PNG, bytes of no format), 4 and 8 are not read (a
    # BMP, a 16-bit PNG), 10 is of the wrong size.
    assert measured == counts(left=20, right=20, frames=15, wrong_size=1, unsupported=2,
                              undecodable=2, frames_dropped=5), bag.images.problems
    assert sorted(good) == [f.t_us for f in bag.frames]
    for frame in bag.frames:
        left, right = good[frame.t_us]
        np.testing.assert_array_equal(frame.left, stereonav.harris(left))
        np.testing.assert_array_equal(frame.right, stereonav.harris(right))

    python = stereonav.replay(path, PLAIN_RIG, **CTOPICS).summary
    assert summary_counts(python) == measured
    command_line = cli_summary(cli, "replay", path, "--rig", PLAIN_RIG, *topic_args(CTOPICS))
    assert_same_summary(python, command_line)


def test_a_jpeg_cut_short_is_undecodable(scratch: pathlib.Path) -> None:
    frames = []
    for k in range(6):
        t = T0_US + k * INTERVAL_US
        left, right = lamps(k), lamps(k, shift=20)
        jpeg = [cv2.imencode(".jpg", image)[1].tobytes() for image in (left, right)]
        if k == 3:
            assert cv2.imdecode(np.frombuffer(jpeg[1][: len(jpeg[1]) // 2], np.uint8), 0) is None
            jpeg[1] = jpeg[1][: len(jpeg[1]) // 2]  # the second half lost
        frames.append((t, (t, Compressed(jpeg[0], "jpeg")), (t, Compressed(jpeg[1], "jpeg"))))
    path = write_bag("mcap_ros2", scratch, "cut-jpeg", frames, odometry_rows(T0_US, T0_US + 300_000, 1),
                     CLEFT, CRIGHT)
    bag = stereonav.read_bag(path, PLAIN_RIG, **CTOPICS)
    assert counts_of(bag.images) == counts(left=6, right=6, frames=5, undecodable=1, frames_dropped=1)


def test_a_bag_written_topic_by_topic_pairs_every_frame(scratch: pathlib.Path) -> None:
    out = bags.writer("mcap_ros2", scratch, "topic-by-topic")
    stamps = [T0_US + k * INTERVAL_US for k in range(40)]
    for k, t in enumerate(stamps):  # every left image, then every right one, then odometry
        out.image(LEFT, t, Raw.of(lamps(k), "mono8"))
    for k, t in enumerate(stamps):
        out.image(RIGHT, t, Raw.of(lamps(k, shift=20), "mono8"))
    for row in odometry_rows(stamps[0], stamps[-1], 3):
        out.odom(ODOM, int(row[0]), 0.1, 0.0, 0.0)
    bag = stereonav.read_bag(out.close(), PLAIN_RIG, **TOPICS)
    assert counts_of(bag.images) == counts(left=40, right=40, frames=40)


# --- Errors ----------------------------------------------------------------------------------------


def test_missing_topics_and_wrong_types_are_one_line_errors(scratch: pathlib.Path, cli: pathlib.Path) -> None:
    path, _, _ = imperfect_bag("mcap_ros2", "raw", scratch)
    cases = {
        "missing": ({**TOPICS, "right": "/cam3/image_raw"}, ["--right /cam3/image_raw", "no such topic",
                                                             f"{RIGHT} (sensor_msgs/msg/Image)"]),
        "one topic for two roles": ({**TOPICS, "left": ODOM}, [f"--left and --odom both name {ODOM}"]),
        "odometry as a camera": ({**TOPICS, "left": ODOM, "odom": "/odom2"},
                                 [f"topic {ODOM} (left camera)", "nav_msgs/msg/Odometry", "not sensor_msgs/msg/Image"]),
        "a camera as odometry": ({**TOPICS, "odom": THIRD}, [f"topic {THIRD} (odometry)", "not nav_msgs/msg/Odometry"]),
    }
    for name, (topics, words) in cases.items():
        with pytest.raises(stereonav.InputError) as python:
            stereonav.replay(path, PLAIN_RIG, **topics)
        with pytest.raises(stereonav.InputError) as read:
            stereonav.read_bag(path, PLAIN_RIG, **topics)
        done = run_cli(cli, "replay", path, "--rig", PLAIN_RIG, *topic_args(topics), ok=False)
        assert done.returncode != 0, name
        line = done.stderr.strip()
        one_line(line)
        one_line(str(python.value))
        assert str(python.value) == str(read.value), name
        assert line == f"stereonav: error: {python.value}", (name, line)
        for word in words:
            assert word in line, (name, word, line)
    # The bag without its topics named: the replay names its camera and odometry topics.
    with pytest.raises(stereonav.InputError, match="name its camera and odometry topics") as e:
        stereonav.replay(path, PLAIN_RIG)
    one_line(str(e.value))
    assert f"{LEFT} (sensor_msgs/msg/Image)" in str(e.value) and ODOM in str(e.value)


def test_a_topic_named_twice_is_refused_as_such(scratch: pathlib.Path) -> None:
    path, _, _ = imperfect_bag("mcap_ros2", "raw", scratch)
    with pytest.raises(stereonav.InputError) as e:
        stereonav.replay(path, PLAIN_RIG, left=LEFT, right=RIGHT, odom=RIGHT)
    assert RIGHT in str(e.value) and "no such topic" not in str(e.value), str(e.value)


def test_topics_are_named_all_three_or_none(scratch: pathlib.Path) -> None:
    path, _, _ = imperfect_bag("mcap_ros2", "raw", scratch)
    with pytest.raises(stereonav.InputError, match=r'right and odom missing \(given left="/cam0/image_raw"\)'):
        stereonav.replay(path, PLAIN_RIG, left=LEFT)
    with pytest.raises(ValueError, match="odom missing"):
        stereonav.localize(path, path, PLAIN_RIG, left=LEFT, right=RIGHT)
    with pytest.raises(stereonav.InputError, match="left is an empty topic name"):
        stereonav.replay(path, PLAIN_RIG, left="", right=RIGHT, odom=ODOM)
    for call in (stereonav.replay, stereonav.read_bag):
        with pytest.raises(TypeError, match="left must be a topic name"):
            call(path, PLAIN_RIG, left=3, right=RIGHT, odom=ODOM)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="odom must be a topic name"):
        stereonav.localize(path, path, odom=b"/odom")  # type: ignore[arg-type]
    # read_bag: both cameras or neither, a rig with them, something named.
    with pytest.raises(stereonav.InputError, match="left is named without right"):
        stereonav.read_bag(path, PLAIN_RIG, left=LEFT, odom=ODOM)
    with pytest.raises(stereonav.InputError, match="needs a rig"):
        stereonav.read_bag(path, left=LEFT, right=RIGHT)
    with pytest.raises(stereonav.InputError, match="no topic named"):
        stereonav.read_bag(path, PLAIN_RIG)
    with pytest.raises(stereonav.InputError, match="does-not-exist.mcap") as e:
        stereonav.read_bag(scratch / "does-not-exist.mcap", odom=ODOM)
    assert isinstance(e.value.__cause__, FileNotFoundError)


def test_decode_image_takes_bytes_and_names_what_it_cannot_read() -> None:
    image = lamps(3)
    png = cv2.imencode(".png", image)[1]
    for data in (png.tobytes(), bytearray(png.tobytes()), memoryview(png.tobytes()), png.ravel()):
        decoded = stereonav.decode_image(data)
        assert decoded.dtype == np.uint8 and decoded.flags.c_contiguous
        np.testing.assert_array_equal(decoded, image)
    rgb = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    rgb[..., 0] = 200  # blue: the decode takes RGB to gray with OpenCV's weights
    np.testing.assert_array_equal(
        stereonav.decode_image(cv2.imencode(".png", rgb)[1]), cv2.cvtColor(rgb, cv2.COLOR_BGR2GRAY)
    )
    with pytest.raises(TypeError, match="data must be bytes"):
        stereonav.decode_image("image.png")  # type: ignore[arg-type]
    with pytest.raises(stereonav.InputError, match="neither PNG nor JPEG"):
        stereonav.decode_image(b"not an image at all")
    with pytest.raises(stereonav.InputError, match="L16|16"):
        stereonav.decode_image(cv2.imencode(".png", image.astype(np.uint16) * 257)[1])


# --- Odometry on a third party's bag ----------------------------------------------------------------


def test_odometry_of_a_real_third_party_bag_equals_mcap_ros2s(cli: pathlib.Path) -> None:
    if not TURTLEBOT.is_file():
        pytest.skip(f"no {TURTLEBOT} (the shared data folder is absent)")
    bag = stereonav.read_bag(TURTLEBOT, odom="/odom")
    assert bag.images is None and bag.frames == ()
    assert bag.topics == {"odom": ("/odom", "nav_msgs/msg/Odometry")}
    theirs = bags.read_odometry(TURTLEBOT, "/odom")
    assert len(theirs) == 2639 == bag.messages["odom"]
    ours = np.column_stack([bag.odometry[f] for f in ("t_us", "vx", "vy", "vtheta")])
    np.testing.assert_array_equal(ours, theirs)
    assert np.abs(bag.odometry["vx"]).max() > 0.1 and np.abs(bag.odometry["vtheta"]).max() > 0.1
    # It has no cameras: a replay naming camera topics says which topics it has.
    with pytest.raises(stereonav.InputError, match="--left /cam0/image_raw: the bag has no such topic"):
        stereonav.replay(TURTLEBOT, PLAIN_RIG, **TOPICS)
    done = run_cli(cli, "replay", TURTLEBOT, "--rig", PLAIN_RIG, *topic_args(TOPICS), ok=False)
    assert done.returncode != 0 and "/amcl_pose (geometry_msgs/msg/PoseWithCovarianceStamped)" in done.stderr
    one_line(done.stderr)


# --- localize and the fleet ------------------------------------------------------------------------


def lamp_map(directory: pathlib.Path) -> pathlib.Path:
    """A map of three lamps from a lighting plan (``stereonav.import_map``)."""
    plan, path = directory / "lamps.csv", directory / "lamps.map"
    if not path.exists():
        plan.write_text("x,y,z\n0.0,0.0,3.0\n1.0,0.5,3.0\n2.0,-0.5,3.0\n")
        stereonav.import_map(plan, path)
    return path


def test_localize_takes_the_topics(scratch: pathlib.Path, cli: pathlib.Path) -> None:
    path, expected, _ = imperfect_bag("rosbags", "raw", scratch)
    run = stereonav.localize(path, lamp_map(scratch), PLAIN_RIG, **TOPICS)
    assert run.summary["frames"] == expected["frames"] == len(run.trajectory)
    command_line = cli_summary(cli, "localize", path, "--map", lamp_map(scratch), "--rig", PLAIN_RIG,
                               *topic_args(TOPICS))
    assert_same_summary(run.summary, command_line)
    with pytest.raises(stereonav.InputError, match="no such topic"):
        stereonav.localize(path, lamp_map(scratch), PLAIN_RIG, **{**TOPICS, "odom": "/wheels"})


def test_localize_reports_what_became_of_the_images(scratch: pathlib.Path) -> None:
    path, expected, _ = imperfect_bag("rosbags", "raw", scratch)
    summary = stereonav.localize(path, lamp_map(scratch), PLAIN_RIG, **TOPICS).summary
    assert summary_counts(summary) == expected
    assert any("could not be read" in w for w in summary["warnings"]), summary["warnings"]


def test_the_fleet_replays_bags_with_their_topics(scratch: pathlib.Path) -> None:
    fleet = pytest.importorskip("stereonav.fleet")
    distributed = pytest.importorskip("distributed")
    logs = [imperfect_bag(writer, "raw", scratch)[0] for writer in WRITERS]
    with distributed.Client(processes=False, n_workers=1, threads_per_worker=2,
                            dashboard_address=None) as client:
        table = fleet.replay_logs(logs, PLAIN_RIG, scheduler=client, progress=False, **TOPICS)
    for log, (_, row) in zip(logs, table.iterrows()):
        assert row["error"] is None, row["error"]
        expected = fleet.summary_row(str(log), stereonav.replay(log, PLAIN_RIG, **TOPICS).summary)
        for column in ("frames", "landmarks", "counts_images_left", "counts_images_unpaired",
                       "counts_image_frames_dropped", "baseline", "baseline_sigma"):
            assert row[column] == expected[column], column
        assert row["counts_images_wrong_size"] == 1
    with pytest.raises(stereonav.InputError, match="odom missing"):
        fleet.replay_logs(logs, PLAIN_RIG, left=LEFT, right=RIGHT, progress=False)
    with pytest.raises(SystemExit):
        fleet.main([str(logs[0]), "--rig", str(PLAIN_RIG), "--left", LEFT, "--out", str(scratch / "t.csv")])


# --- End to end: the simulator's bag through both Python writers ----------------------------------


def simulator_writes_ros2(cli: pathlib.Path) -> bool:
    return "--ros2" in run_cli(cli, "simulate", "--help").stdout


SIM_TOPICS = {"left": "/cam0/image_raw/compressed", "right": "/cam1/image_raw/compressed", "odom": "/odom"}


@pytest.mark.slow
def test_the_simulated_experiment_as_a_jpeg_bag_replays_through_every_writer(
    scratch: pathlib.Path, cli: pathlib.Path
) -> None:
    if not simulator_writes_ros2(cli):
        pytest.skip("stereonav simulate has no --ros2 yet: the simulator cannot write a ROS 2 bag")
    scenario = SCENARIOS / "paper-experiment-radtan.toml"
    rig = SCENARIOS / "paper-experiment-radtan.rig.toml"
    original = scratch / "radtan-jpeg.mcap"
    run_cli(cli, "simulate", scenario, "--out", original, "--ros2", "jpeg")
    logs = {"simulator": original}
    for writer in WRITERS:
        logs[writer] = bags.rewrite(original, writer, scratch, f"radtan-jpeg-{writer}", list(SIM_TOPICS.values()))
    summaries = {}
    for name, log in logs.items():
        python = stereonav.replay(log, rig, skip_phase1=True, **SIM_TOPICS).summary
        assert_same_summary(python, cli_summary(cli, "replay", log, "--rig", rig, "--skip-phase1",
                                                *topic_args(SIM_TOPICS)))
        summaries[name] = python
        images = summary_counts(python)
        print(name, images, len(python["landmarks"]), python["camera"]["baseline"])
        assert images["frames"] > 0 and images["left"] == images["right"] == images["frames"]
        assert images["unpaired"] == images["wrong_size"] == images["unsupported"] == 0
        assert images["undecodable"] == images["frames_dropped"] == 0
        # The five lamps mapped, the baseline known to a millimetre.
        assert len(python["landmarks"]) == 5
        assert python["camera"]["baseline"]["sigma"] < 0.001
    # Against the simulator's truth (measured: the five lamps within 1 mm rms, the baseline
    # 4 um off with a sigma of 0.15 mm, the trajectory within 2 mm rms).
    truth = summaries["simulator"]["truth"]
    assert truth["landmarks_matched"] == 5 and truth["landmarks_unmatched"] == 0, truth
    assert truth["landmark_rms_m"] < 0.01 and truth["ate_rms_m"] < 0.02, truth
    baseline = summaries["simulator"]["camera"]["baseline"]
    assert abs(truth["camera"]["baseline"]) < 3 * baseline["sigma"], (truth["camera"], baseline)
    # The stack reads the same images and odometry whichever writer wrote them (the rewritten
    # bags carry the cameras and the odometry only, not the simulator's /truth topics).
    for writer in WRITERS:
        assert_same_summary(
            {k: v for k, v in summaries[writer].items() if k != "truth"},
            {k: v for k, v in summaries["simulator"].items() if k != "truth"},
        )
